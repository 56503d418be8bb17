"""The generative garment subspace (the paper's Sec. 3.4): a variational autoencoder whose decoder
D maps a latent code z (25 numbers) to a canonical garment X ``(N, 3)`` (metres, the garment
model's unposed, deshaped space). The regressor predicts z per frame; D turns it into X.

Shapes: B a batch (frames), N garment vertices, L the latent size, K the basis size of a
``basis`` decoder. Both networks work on per-vertex normalised coordinates
``(X − mean) / std``, with ``mean`` and ``std`` ``(N, 3)`` buffers set from the training data.
"""

from __future__ import annotations

import itertools
import math
import pickle
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from usd_garment.atomic import atomic_output

#: Size of the latent code (the paper's 25).
LATENT_SIZE = 25
#: Kinds of decoder: a plain MLP to 3N outputs, or an MLP to K coefficients of a learned basis.
DECODER_KINDS = ("mlp", "basis")
#: Lower bound of the per-vertex standard deviation (m), so near-static vertices do not blow up
#: the normalised coordinates.
STD_FLOOR = 1e-4
#: Frames used, evenly spaced, for the principal-component start of a basis decoder.
PCA_FRAMES = 1024
#: Tensors ``save_vae`` always stores in float32: the per-vertex statistics (m).
KEEP_FLOAT32 = ("mean", "std")
#: Version of the file written by ``save_vae``.
FORMAT_VERSION = 1


@dataclass(frozen=True)
class DecoderConfig:
    """Architecture of the decoder D: z ``(B, L)`` → X ``(B, N, 3)``.

    Attributes:
        kind: ``mlp``: hidden layers, then one linear layer to 3N normalised coordinates (the
            official decoder is ``mlp`` with ``hidden=(2000,) * 4``, ~39 M parameters for the
            T-shirt); ``basis``: hidden layers, then a linear layer to ``basis_size`` K
            coefficients, times a learned basis ``(K, 3N)`` plus a learned offset (the
            parameters are dominated by K·3N, so K sets the size).
        hidden: widths of the hidden layers (each Linear → ReLU → LayerNorm when
            ``layer_norm``, else Linear → ReLU).
        basis_size: K, for ``basis`` only.
        layer_norm: LayerNorm after each hidden ReLU, as the official decoder.
    """

    kind: str = "basis"
    hidden: tuple[int, ...] = (256, 256)
    basis_size: int = 64
    layer_norm: bool = True

    def __post_init__(self) -> None:
        if self.kind not in DECODER_KINDS:
            raise ValueError(f"decoder kind {self.kind!r}: expected one of {DECODER_KINDS}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        if any(h < 1 for h in self.hidden) or self.basis_size < 1:
            raise ValueError("decoder widths must be positive")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (``hidden`` as a list)."""
        out = asdict(self)
        out["hidden"] = list(self.hidden)
        return out

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> DecoderConfig:
        """Inverse of ``to_dict``."""
        return cls(**{**values, "hidden": tuple(values.get("hidden", cls.hidden))})


#: The decoder of the official inference code (25 → 4×2000 ReLU+LayerNorm → 3N).
OFFICIAL_DECODER = DecoderConfig(kind="mlp", hidden=(2000, 2000, 2000, 2000), layer_norm=True)


def _mlp(sizes: list[int], layer_norm: bool) -> nn.Sequential:
    """Linear → ReLU (→ LayerNorm) for each consecutive pair of ``sizes``."""
    layers: list[nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), nn.ReLU()]
        if layer_norm:
            layers.append(nn.LayerNorm(b))
    return nn.Sequential(*layers)


class GarmentDecoder(nn.Module):
    """D: latent codes ``(B, L)`` → normalised coordinates ``(B, 3N)`` (see ``DecoderConfig``).

    Denormalisation lives in ``GarmentVAE.decode``, which owns the statistics.
    """

    def __init__(self, num_vertices: int, latent_size: int, config: DecoderConfig) -> None:
        super().__init__()
        self.config = config
        width = [latent_size, *config.hidden]
        self.hidden = _mlp(width, config.layer_norm)
        outputs = 3 * num_vertices
        if config.kind == "mlp":
            self.head = nn.Linear(width[-1], outputs)
            self.basis: nn.Linear | None = None
        else:
            self.head = nn.Linear(width[-1], config.basis_size)
            self.basis = nn.Linear(config.basis_size, outputs)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """Normalised coordinates ``(B, 3N)`` of latent codes ``z`` ``(B, L)``."""
        out = self.head(self.hidden(z))
        return out if self.basis is None else self.basis(out)


class GarmentEncoder(nn.Module):
    """E: normalised coordinates ``(B, 3N)`` → μ ``(B, L)`` and log σ² ``(B, L)``."""

    def __init__(
        self, num_vertices: int, latent_size: int, hidden: tuple[int, ...], layer_norm: bool
    ) -> None:
        super().__init__()
        width = [3 * num_vertices, *hidden]
        self.hidden = _mlp(width, layer_norm)
        self.head = nn.Linear(width[-1], 2 * latent_size)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mu, logvar = self.head(self.hidden(x)).chunk(2, dim=-1)
        return mu, logvar.clamp(-30.0, 20.0)


class GarmentVAE(nn.Module):
    """The VAE of canonical garments: E(X) → (μ, log σ²), z = μ + σ·ε, D(z) → X.

    Args:
        num_vertices: N, the garment template's vertex count.
        latent_size: L (the paper's 25).
        encoder_hidden: widths of the encoder's hidden layers (its first layer, 3N × width, is
            most of its size; the encoder is needed for training and for encoding the regressor's
            targets, not at run time); None: a decoder-only model, whose ``encode`` raises.
        decoder: the decoder's architecture.
        layer_norm: LayerNorm after each hidden ReLU of the encoder.

    Buffers ``mean`` and ``std`` ``(N, 3)`` (m) start at 0 and 1; ``set_statistics`` sets them
    from training data.
    """

    def __init__(
        self,
        num_vertices: int,
        latent_size: int = LATENT_SIZE,
        encoder_hidden: tuple[int, ...] | None = (256, 256),
        decoder: DecoderConfig | None = None,
        layer_norm: bool = True,
    ) -> None:
        super().__init__()
        self.num_vertices = int(num_vertices)
        self.latent_size = int(latent_size)
        self.encoder_hidden = None if encoder_hidden is None else tuple(map(int, encoder_hidden))
        self.layer_norm = bool(layer_norm)
        self.decoder_config = decoder if decoder is not None else DecoderConfig()
        self.encoder: GarmentEncoder | None = None
        if self.encoder_hidden is not None:
            self.encoder = GarmentEncoder(
                self.num_vertices, self.latent_size, self.encoder_hidden, self.layer_norm
            )
        self.decoder = GarmentDecoder(self.num_vertices, self.latent_size, self.decoder_config)
        self.register_buffer("mean", torch.zeros(self.num_vertices, 3))
        self.register_buffer("std", torch.ones(self.num_vertices, 3))

    # -- configuration --------------------------------------------------------------------

    def config(self) -> dict[str, Any]:
        """JSON-able architecture; ``GarmentVAE.from_config`` rebuilds the model (weights and
        statistics come from the state dict)."""
        return {
            "num_vertices": self.num_vertices,
            "latent_size": self.latent_size,
            "encoder_hidden": None if self.encoder_hidden is None else list(self.encoder_hidden),
            "layer_norm": self.layer_norm,
            "decoder": self.decoder_config.to_dict(),
        }

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> GarmentVAE:
        """A fresh model with the architecture ``config`` (from ``config()``)."""
        return cls(
            num_vertices=config["num_vertices"],
            latent_size=config["latent_size"],
            encoder_hidden=config["encoder_hidden"],
            decoder=DecoderConfig.from_dict(config["decoder"]),
            layer_norm=config.get("layer_norm", True),
        )

    # -- data statistics ------------------------------------------------------------------

    @torch.no_grad()
    def set_statistics(self, x: torch.Tensor, pca_init: bool = True) -> None:
        """Set the per-vertex ``mean`` and ``std`` from training garments ``x`` ``(T, N, 3)``
        (m); with ``pca_init`` and a ``basis`` decoder, also start its basis at the leading
        principal components of the normalised data (at most ``PCA_FRAMES`` frames, evenly
        spaced), each scaled by its standard deviation, and its offset at zero (the basis
        columns beyond the data's rank keep their random start)."""
        x = x.to(self.mean)
        self.mean.copy_(x.mean(0))
        self.std.copy_(x.std(0, unbiased=False).clamp_min(STD_FLOOR))
        basis = self.decoder.basis
        if not pca_init or basis is None:
            return
        step = max(1, math.ceil(x.shape[0] / PCA_FRAMES))
        xn = self.normalise(x[::step]).flatten(1).double()
        xn = xn - xn.mean(0)
        _, s, vh = torch.linalg.svd(xn, full_matrices=False)
        k = min(basis.weight.shape[1], vh.shape[0])
        scale = s[:k] / math.sqrt(xn.shape[0])
        basis.weight[:, :k] = (vh[:k].T * scale).to(basis.weight)
        basis.bias.zero_()

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """``(X − mean) / std``, ``(..., N, 3)``."""
        return (x - self.mean) / self.std

    def denormalise(self, xn: torch.Tensor) -> torch.Tensor:
        """``mean + std · Xn``, ``(..., N, 3)`` (m)."""
        return self.mean + self.std * xn

    # -- networks -------------------------------------------------------------------------

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """E: garments ``x`` ``(B, N, 3)`` (m) → μ ``(B, L)``, log σ² ``(B, L)``.

        Raises:
            RuntimeError: a decoder-only model.
        """
        if self.encoder is None:
            raise RuntimeError("this garment VAE has no encoder (stored decoder-only)")
        return self.encoder(self.normalise(x).flatten(-2))

    def decoder_only(self) -> GarmentVAE:
        """A copy without the encoder (what the stage processor needs), sharing nothing."""
        config = self.config() | {"encoder_hidden": None}
        out = GarmentVAE.from_config(config).to(self.mean.device)
        state = {k: v for k, v in self.state_dict().items() if not k.startswith("encoder.")}
        out.load_state_dict(state)
        return out.train(self.training)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """D: latent codes ``z`` ``(B, L)`` → garments ``(B, N, 3)`` (m)."""
        xn = self.decoder(z).unflatten(-1, (self.num_vertices, 3))
        return self.denormalise(xn)

    def forward(
        self, x: torch.Tensor, generator: torch.Generator | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """D(z) with z = μ + σ·ε in training mode (ε ~ N(0, I) from ``generator``), z = μ in
        evaluation mode.

        Args:
            x: garments ``(B, N, 3)`` (m).
            generator: CPU random source of ε (drawn on the CPU and moved to the model's
                device, so that a seed gives the same draws on every device); None: torch's
                default CPU generator.

        Returns:
            reconstruction ``(B, N, 3)`` (m), μ ``(B, L)``, log σ² ``(B, L)``.
        """
        mu, logvar = self.encode(x)
        z = mu
        if self.training:
            eps = torch.randn(mu.shape, generator=generator, dtype=mu.dtype).to(mu.device)
            z = mu + eps * (0.5 * logvar).exp()
        return self.decode(z), mu, logvar


def num_parameters(module: nn.Module) -> int:
    """Count of trainable and frozen parameters (buffers excluded)."""
    return sum(p.numel() for p in module.parameters())


def decoder_bytes(model: GarmentVAE, bytes_per_value: int = 4) -> int:
    """Size of what decoding needs, as ``save_vae(..., encoder=False)`` stores it: the decoder's
    parameters at ``bytes_per_value`` (4: float32, 2: float16) plus ``mean`` and ``std`` in
    float32."""
    statistics = model.mean.numel() + model.std.numel()
    return num_parameters(model.decoder) * bytes_per_value + 4 * statistics


@dataclass
class VaeFile:
    """A trained VAE as stored by ``save_vae``: the model and JSON-able metadata (training
    configuration, history, data provenance)."""

    model: GarmentVAE
    metadata: dict[str, Any] = field(default_factory=dict)


def save_vae(
    path: str | Path,
    model: GarmentVAE,
    metadata: dict[str, Any] | None = None,
    *,
    encoder: bool = True,
    dtype: torch.dtype = torch.float32,
) -> None:
    """Write ``model`` (architecture, weights, statistics) and ``metadata`` to ``path``
    atomically (``torch.save`` of tensors, lists and numbers only).

    Args:
        encoder: keep the encoder; False writes a decoder-only model (what run time needs).
        dtype: storage type of the weights (``torch.float16`` halves the file; the statistics
            stay float32, as float16 would round positions by up to 0.1 mm; ``load_vae``
            computes in float32 either way).
    """
    if not encoder and model.encoder is not None:
        model = model.decoder_only()
    payload = {
        "format": FORMAT_VERSION,
        "config": model.config(),
        "state": {
            k: v.detach().cpu().to(dtype) if k not in KEEP_FLOAT32 else v.detach().cpu()
            for k, v in model.state_dict().items()
        },
        "metadata": metadata or {},
    }
    with atomic_output(path) as tmp:
        torch.save(payload, tmp)


def load_vae(path: str | Path, map_location: str | torch.device = "cpu") -> VaeFile:
    """Read a file written by ``save_vae``; the model is float32, in evaluation mode.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a VAE file, or an unknown format version.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        payload = torch.load(path, map_location=map_location, weights_only=True)
        version = payload["format"]
        config = payload["config"]
        state = payload["state"]
    except (OSError, RuntimeError, KeyError, TypeError, ValueError, pickle.UnpicklingError) as exc:
        raise ValueError(f"{path}: not a garment VAE file ({exc})") from exc
    if version != FORMAT_VERSION:
        raise ValueError(f"{path}: VAE file format {version}, expected {FORMAT_VERSION}")
    model = GarmentVAE.from_config(config)
    model.load_state_dict(state)
    model.eval()
    return VaeFile(model=model, metadata=payload.get("metadata", {}))
