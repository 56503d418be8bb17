"""Training the generative garment subspace (the paper's Sec. 3.4): the VAE on the canonical
training set's ``train`` split with L_rec + λ1 L_laplacian + λ2 L_collision + λ3 L_KL, where
L_collision checks the reconstructions and, self-supervised, the decodings of random latents
against the constant canonical body SDF; evaluated after every epoch on the ``validation`` split
(the paper's Fig. 4: collisions during training, with and without the self-supervised term).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch

from usd_garment.atomic import atomic_output
from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.generative.losses import (
    COLLISION_EPSILON,
    UniformLaplacian,
    collision_loss,
    kl_loss,
    laplacian_loss,
    reconstruction_loss,
)
from usd_garment.generative.vae import LATENT_SIZE, DecoderConfig, GarmentVAE
from usd_garment.training.finite import require_finite

#: ``progress(epoch, total, history_row)``, called after each epoch (epochs count from 1).
Progress = Callable[[int, int, dict[str, Any]], None]
#: What a checkpoint of ``train_vae`` says it is ...
CHECKPOINT_KIND = "garment-vae"
#: ... and the version of its layout.
CHECKPOINT_VERSION = 1
#: Vertices within this distance (m) of the body count as "near" in the evaluation.
NEAR_MARGIN = 1e-3
#: Frames per forward pass in the evaluation.
EVAL_BATCH = 256
#: The training terms averaged per epoch in the history.
TRAIN_TERMS = ("loss", "rec", "laplacian", "collision_rec", "collision_random", "kl")
#: The figures of ``evaluate_vae``.
EVAL_FIGURES = ("rec_l1_mm", "rec_dist_mm", "rec_max_mm", "rec_inside_pct", "rec_near_pct",
                "rand_inside_pct", "rand_near_pct")  # fmt: skip
#: Settings that may differ between a checkpoint and the run resuming it.
RESUMABLE = ("epochs", "device")


class HasSdf(Protocol):
    """Anything with the canonical body SDF, e.g. ``BodyFields``."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor: ...


@dataclass
class VaeTrainConfig:
    """Settings of one VAE training run; stored in its history and checkpoint.

    Attributes:
        epochs: passes over the training frames.
        batch_size: training frames per step.
        lr: Adam's learning rate at epoch 1 ...
        lr_decay: ... multiplied by this after every epoch.
        lambda_laplacian: λ1.
        lambda_collision: λ2 (on each of the two collision terms).
        lambda_kl: λ3; with the L1 terms summed per garment in metres, the scale of the Laplace
            likelihood they stand for (m).
        epsilon: ε of the collision term (m).
        collision: use L_collision at all (False: the paper's "w/o collision loss").
        self_supervised: add its second, self-supervised term on decodings of
            ``self_supervised_batch`` latents z ~ N(0, I) per step (False: the paper's "w/o
            self-supervised term"); only read when ``collision`` is on.
        self_supervised_batch: random latents per step.
        latent_size: L.
        encoder_hidden: widths of the encoder's hidden layers.
        decoder: the decoder's architecture.
        pca_init: start a basis decoder's basis at the data's principal components.
        eval_random: random latents (fixed per run, from ``seed``) decoded in each evaluation.
        skip_flagged_frames: leave the training frames that the simulation flagged (kept though
            they failed its checks) out of the training and of the statistics; the validation
            frames stay all.
        seed: seeds the weights, the batch order and every random draw.
        device: torch device of the run.
    """

    epochs: int = 100
    batch_size: int = 64
    lr: float = 1e-3
    lr_decay: float = 0.98
    lambda_laplacian: float = 1.0
    lambda_collision: float = 10.0
    lambda_kl: float = 1e-3
    epsilon: float = COLLISION_EPSILON
    collision: bool = True
    self_supervised: bool = True
    self_supervised_batch: int = 64
    latent_size: int = LATENT_SIZE
    encoder_hidden: tuple[int, ...] = (256, 256)
    decoder: DecoderConfig = field(default_factory=DecoderConfig)
    pca_init: bool = True
    eval_random: int = 1024
    skip_flagged_frames: bool = False
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self) -> None:
        self.encoder_hidden = tuple(int(h) for h in self.encoder_hidden)
        if isinstance(self.decoder, dict):
            self.decoder = DecoderConfig.from_dict(self.decoder)
        require_finite(self)
        if self.epochs < 0 or self.batch_size < 1 or self.self_supervised_batch < 1:
            raise ValueError("epochs must be >= 0 and batch sizes >= 1")

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form."""
        out = asdict(self)
        out["encoder_hidden"] = list(self.encoder_hidden)
        out["decoder"] = self.decoder.to_dict()
        return out

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> VaeTrainConfig:
        """Inverse of ``to_dict``; unknown keys raise ``TypeError``."""
        return cls(**values)

    @property
    def uses_self_supervision(self) -> bool:
        return self.collision and self.self_supervised


def split_frames(data: CanonicalSet, split: str) -> np.ndarray:
    """Frame indices ``(T_split,)`` of the sequences in ``split``, in sequence order."""
    parts = [np.arange(data.sequence(s).start, data.sequence(s).stop) for s in
             data.split_sequences(split)]  # fmt: skip
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def build_vae(config: VaeTrainConfig, num_vertices: int) -> GarmentVAE:
    """The untrained model of ``config``, its weights drawn from ``config.seed`` (torch's
    global random state is left as it was)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        return GarmentVAE(
            num_vertices,
            latent_size=config.latent_size,
            encoder_hidden=config.encoder_hidden,
            decoder=config.decoder,
        )


def _random_latents(config: VaeTrainConfig) -> torch.Tensor:
    """The run's fixed evaluation latents ``(eval_random, L)`` (CPU)."""
    gen = torch.Generator().manual_seed(config.seed + 7919)
    return torch.randn(config.eval_random, config.latent_size, generator=gen)


@torch.no_grad()
def evaluate_vae(
    model: GarmentVAE,
    frames: torch.Tensor,
    sdf: Callable[[torch.Tensor], torch.Tensor],
    latents: torch.Tensor | None = None,
    batch: int = EVAL_BATCH,
) -> dict[str, float | None]:
    """Figures of ``model`` (in evaluation mode, z = μ) on garments ``frames`` ``(T, N, 3)``
    (m) and on the decodings of ``latents`` ``(R, L)``.

    Returns:
        ``rec_l1_mm`` mean absolute coordinate error, ``rec_dist_mm`` mean vertex distance,
        ``rec_max_mm`` largest vertex distance (mm); ``rec_inside_pct`` / ``rec_near_pct`` share
        of reconstructed vertices inside the body / within ``NEAR_MARGIN`` of it (%);
        ``rand_inside_pct`` / ``rand_near_pct`` the same for the random decodings. Figures whose
        input is empty are None.
    """
    was_training = model.training
    model.eval()
    device = model.mean.device
    out: dict[str, float | None] = dict.fromkeys(EVAL_FIGURES)
    n = model.num_vertices
    if len(frames):
        l1 = dist = worst = inside = near = 0.0
        for start in range(0, len(frames), batch):
            x = frames[start : start + batch].to(device)
            rec, _, _ = model(x)
            l1 += float((rec - x).abs().sum())
            d = (rec - x).norm(dim=-1)
            dist += float(d.sum())
            worst = max(worst, float(d.max()))
            s = sdf(rec)
            inside += float((s < 0).sum())
            near += float((s < NEAR_MARGIN).sum())
        count = len(frames) * n
        out |= {
            "rec_l1_mm": 1e3 * l1 / (3 * count),
            "rec_dist_mm": 1e3 * dist / count,
            "rec_max_mm": 1e3 * worst,
            "rec_inside_pct": 100.0 * inside / count,
            "rec_near_pct": 100.0 * near / count,
        }
    if latents is not None and len(latents):
        inside = near = 0.0
        for start in range(0, len(latents), batch):
            s = sdf(model.decode(latents[start : start + batch].to(device)))
            inside += float((s < 0).sum())
            near += float((s < NEAR_MARGIN).sum())
        count = len(latents) * n
        out |= {"rand_inside_pct": 100.0 * inside / count, "rand_near_pct": 100.0 * near / count}
    model.train(was_training)
    return out


@torch.no_grad()
def _inside_pct(
    x: torch.Tensor, sdf: Callable[[torch.Tensor], torch.Tensor], device: torch.device
) -> float | None:
    """Share (%) of the vertices of garments ``x`` ``(T, N, 3)`` inside the body; None if empty."""
    if not len(x):
        return None
    inside = sum(
        float((sdf(x[i : i + EVAL_BATCH].to(device)) < 0).sum())
        for i in range(0, len(x), EVAL_BATCH)
    )
    return 100.0 * inside / (x.shape[0] * x.shape[1])


def _save_checkpoint(path: Path, state: dict[str, Any]) -> None:
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def _check_resumable(saved: dict[str, Any], config: VaeTrainConfig, path: Path) -> None:
    # a setting added after the checkpoint was made had its default then
    saved = {**VaeTrainConfig().to_dict(), **saved}
    a = {k: v for k, v in saved.items() if k not in RESUMABLE}
    b = {k: v for k, v in config.to_dict().items() if k not in RESUMABLE}
    changed = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
    if changed:
        raise ValueError(f"{path}: checkpoint made with other settings ({', '.join(changed)})")


def train_vae(
    data: CanonicalSet,
    config: VaeTrainConfig,
    *,
    fields: HasSdf,
    device: str | torch.device | None = None,
    progress: Progress | None = None,
    checkpoint: str | Path | None = None,
    resume: bool = False,
) -> tuple[GarmentVAE, dict[str, Any]]:
    """Train the garment VAE on ``data``'s ``train`` split, evaluating it after every epoch on
    its ``validation`` split and on ``config.eval_random`` fixed random latents.

    Each step: a batch of training frames X, reconstruction D(z), z = μ + σ·ε, and
    L_rec + λ1 L_laplacian + λ2 (L_col(D(E(X))) + L_col(D(z_rand))) + λ3 L_KL, the collision
    terms as ``config.collision`` / ``config.self_supervised`` say. The statistics (and a basis
    decoder's principal-component start) come from the training frames.

    Args:
        data: the canonical training set.
        config: the run's settings.
        fields: holds the canonical body SDF ``fields.sdf(points (..., N, 3)) -> (..., N)`` (m);
            a torch module is moved to the run's device (in place).
        device: overrides ``config.device`` when given.
        progress: called after every epoch with ``(epoch, config.epochs, history_row)``.
        checkpoint: file written (atomically) after every epoch: model, optimizer, random
            states, epoch and history.
        resume: continue from ``checkpoint`` if that file exists (its epochs count on, up to
            ``config.epochs``, which may be raised; every other setting but ``device`` must
            match; the remaining epochs then match an uninterrupted run on the CPU).

    Returns:
        The trained model (evaluation mode) and the history: ``config``, ``frames`` per split
        (training frames used), ``flagged_frames_skipped``, ``validation_inside_pct`` (the
        ground truth's own share inside the body) and ``epochs``, one row per epoch: ``epoch``,
        ``lr``, ``seconds``, the mean training terms ``loss``, ``rec``, ``laplacian``,
        ``collision_rec``, ``collision_random``, ``kl`` (per garment, m / nats; collision terms
        are measured even when not trained on) and the ``val_*`` figures of ``evaluate_vae``.
        JSON-able.

    The same data and config give the same result on the CPU (seeded weights and draws; the
    global torch random state is left alone); CUDA kernels may not be bitwise deterministic.

    Raises:
        ValueError: no training frames; ``skip_flagged_frames`` on a set without a record of
            them; a resumed checkpoint that is not a VAE checkpoint, or was made with other
            settings or on other data.
        FloatingPointError: the loss is not finite (NaN or infinite).
    """
    device = torch.device(device if device is not None else config.device)
    if isinstance(fields, torch.nn.Module):
        fields.to(device)
    sdf = fields.sdf
    train_idx = split_frames(data, "train")
    flagged = 0
    if config.skip_flagged_frames:
        keep = ~data.flags()[train_idx]
        flagged = int(len(train_idx) - keep.sum())
        train_idx = train_idx[keep]
    val_idx = split_frames(data, "validation")
    if len(train_idx) == 0:
        raise ValueError("the canonical set has no training frames")
    train_x = torch.as_tensor(np.asarray(data.canonical[train_idx], dtype=np.float32))
    val_x = torch.as_tensor(np.asarray(data.canonical[val_idx], dtype=np.float32))
    num_vertices = train_x.shape[1]

    model = build_vae(config, num_vertices)
    model.set_statistics(train_x, pca_init=config.pca_init)
    model.to(device)
    laplacian = UniformLaplacian(data.faces, num_vertices).to(device)
    train_x = train_x.to(device)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    order_gen = torch.Generator().manual_seed(config.seed)
    # on the CPU for every device: a seed draws the same noise on a GPU as on the CPU
    noise_gen = torch.Generator().manual_seed(config.seed + 1)
    latents = _random_latents(config)
    history: dict[str, Any] = {
        "config": config.to_dict(),
        "frames": {"train": len(train_idx), "validation": len(val_idx)},
        "flagged_frames_skipped": flagged,
        "num_vertices": num_vertices,
        "validation_inside_pct": _inside_pct(val_x, sdf, device),
        "epochs": [],
    }
    start_epoch = 0
    path = Path(checkpoint) if checkpoint is not None else None
    if resume and path is not None and path.is_file():
        state = torch.load(path, map_location="cpu", weights_only=True)
        if state.get("kind") != CHECKPOINT_KIND or state.get("version") != CHECKPOINT_VERSION:
            raise ValueError(f"{path}: not a VAE checkpoint (version {CHECKPOINT_VERSION})")
        _check_resumable(state["config"], config, path)
        if state["history"]["frames"] != history["frames"] or state["num_vertices"] != num_vertices:
            raise ValueError(f"{path}: checkpoint made on other data")
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        order_gen.set_state(state["order_rng"])
        noise_gen.set_state(state["noise_rng"])
        history = state["history"]
        history["config"] = config.to_dict()
        start_epoch = int(state["epoch"])

    n_train = len(train_x)
    steps = math.ceil(n_train / config.batch_size)
    for epoch in range(start_epoch, config.epochs):
        t0 = time.perf_counter()
        lr = config.lr * config.lr_decay**epoch
        for group in optimizer.param_groups:
            group["lr"] = lr
        model.train()
        sums = dict.fromkeys(TRAIN_TERMS, 0.0)
        order = torch.randperm(n_train, generator=order_gen).to(device)
        for step in range(steps):
            x = train_x[order[step * config.batch_size : (step + 1) * config.batch_size]]
            rec, mu, logvar = model(x, generator=noise_gen)
            terms = {
                "rec": reconstruction_loss(rec, x),
                "laplacian": laplacian_loss(rec, x, laplacian),
                "kl": kl_loss(mu, logvar),
                "collision_rec": collision_loss(rec, sdf, config.epsilon),
            }
            loss = terms["rec"] + config.lambda_laplacian * terms["laplacian"]
            loss = loss + config.lambda_kl * terms["kl"]
            if config.collision:
                loss = loss + config.lambda_collision * terms["collision_rec"]
            z = torch.randn(
                config.self_supervised_batch, config.latent_size, generator=noise_gen
            ).to(device)
            if config.uses_self_supervision:
                terms["collision_random"] = collision_loss(model.decode(z), sdf, config.epsilon)
                loss = loss + config.lambda_collision * terms["collision_random"]
            else:
                with torch.no_grad():
                    terms["collision_random"] = collision_loss(model.decode(z), sdf, config.epsilon)
            if not torch.isfinite(loss):
                raise FloatingPointError(f"epoch {epoch + 1}, step {step + 1}: loss is {loss}")
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            sums["loss"] += float(loss.detach())
            for key, value in terms.items():
                sums[key] += float(value.detach())
        figures = evaluate_vae(model, val_x, sdf, latents)
        row: dict[str, Any] = {"epoch": epoch + 1, "lr": lr}
        row |= {key: value / steps for key, value in sums.items()}
        row |= {f"val_{key}": value for key, value in figures.items()}
        row["seconds"] = time.perf_counter() - t0
        history["epochs"].append(row)
        if path is not None:
            _save_checkpoint(path, {
                "kind": CHECKPOINT_KIND,
                "version": CHECKPOINT_VERSION,
                "config": config.to_dict(),
                "num_vertices": num_vertices,
                "model_config": model.config(),
                "model": model.state_dict(),
                "optimizer": optimizer.state_dict(),
                "order_rng": order_gen.get_state(),
                "noise_rng": noise_gen.get_state().cpu(),
                "epoch": epoch + 1,
                "history": history,
            })  # fmt: skip
        if progress is not None:
            progress(epoch + 1, config.epochs, row)
    model.eval()
    return model, history
