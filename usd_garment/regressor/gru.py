"""The recurrent garment regressor R(β, γ) of the paper's section 4: stacked GRUs that map each
frame's motion descriptor γ and the body's shape β to the garment's latent code z, carrying a
hidden state from frame to frame so the garment gets dynamics."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

import torch

from usd_garment.body.joints import NUM_BETAS

#: The recurrent state: one ``(1, B, hidden_i)`` tensor per GRU layer.
State = tuple[torch.Tensor, ...]


class GarmentRegressor(torch.nn.Module):
    """``z = R(β, γ)``: per frame ``[γ, β]`` → normalise → GRU layers → linear → denormalise.

    The paper's sizes are 42 → 500 → 500 → 25. Inputs are standardised with stored per-entry
    means and deviations and the output is denormalised with the latent codes' own; these are
    buffers (part of the state dict), set from the training data by :meth:`set_normalization`
    (identity until then).

    Args:
        descriptor_size: entries of γ per frame (42).
        hidden: sizes of the GRU layers.
        latent_size: entries of z per frame (25).
        betas_size: entries of β (10).
    """

    def __init__(
        self,
        descriptor_size: int = 42,
        hidden: tuple[int, ...] | list[int] = (500, 500),
        latent_size: int = 25,
        betas_size: int = NUM_BETAS,
    ) -> None:
        super().__init__()
        if not hidden:
            raise ValueError("hidden needs at least one GRU layer")
        self.descriptor_size = int(descriptor_size)
        self.hidden = tuple(int(h) for h in hidden)
        self.latent_size = int(latent_size)
        self.betas_size = int(betas_size)
        sizes = (self.descriptor_size + self.betas_size, *self.hidden)
        self.layers = torch.nn.ModuleList(
            torch.nn.GRU(sizes[i], sizes[i + 1], batch_first=True) for i in range(len(self.hidden))
        )
        self.output = torch.nn.Linear(self.hidden[-1], self.latent_size)
        n_in = self.descriptor_size + self.betas_size
        self.register_buffer("input_mean", torch.zeros(n_in))
        self.register_buffer("input_std", torch.ones(n_in))
        self.register_buffer("output_mean", torch.zeros(self.latent_size))
        self.register_buffer("output_std", torch.ones(self.latent_size))

    def set_normalization(
        self,
        input_mean: torch.Tensor,
        input_std: torch.Tensor,
        output_mean: torch.Tensor,
        output_std: torch.Tensor,
    ) -> None:
        """Store the standardisation of ``[γ, β]`` ``(descriptor_size + betas_size,)`` and of z
        ``(latent_size,)``; deviations below 1e-6 are replaced by 1 (constant entries)."""
        for name, value in (
            ("input_mean", input_mean),
            ("input_std", input_std),
            ("output_mean", output_mean),
            ("output_std", output_std),
        ):
            buffer = getattr(self, name)
            value = torch.as_tensor(value, dtype=buffer.dtype, device=buffer.device)
            if value.shape != buffer.shape:
                raise ValueError(f"{name} must be {tuple(buffer.shape)}, got {tuple(value.shape)}")
            if name.endswith("std"):
                value = torch.where(value > 1e-6, value, torch.ones_like(value))
            buffer.copy_(value)

    def forward(
        self, gamma: torch.Tensor, betas: torch.Tensor, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """Latent codes of a batch of motions, from a given recurrent state.

        Args:
            gamma: ``(B, T, descriptor_size)`` motion descriptors (see ``regressor.descriptor``).
            betas: ``(B, betas_size)`` body shapes.
            state: the state returned by the previous call on the preceding frames, or None to
                start from rest (zeros). Calling chunk after chunk with the returned state gives
                the output of one call on the whole sequence.

        Returns:
            ``z (B, T, latent_size)`` and the state after the last frame.
        """
        b, t, _ = gamma.shape
        x = torch.cat([gamma, betas[:, None, :].expand(b, t, betas.shape[-1])], dim=-1)
        x = (x - self.input_mean) / self.input_std
        new_state: list[torch.Tensor] = []
        for i, layer in enumerate(self.layers):
            x, h = layer(x, None if state is None else state[i])
            new_state.append(h)
        z = self.output(x) * self.output_std + self.output_mean
        return z, tuple(new_state)

    @torch.no_grad()
    def predict(
        self,
        gamma: torch.Tensor,
        betas: torch.Tensor,
        chunk: int = 1024,
        restarts: Sequence[int] = (),
    ) -> torch.Tensor:
        """Latent codes ``(T, latent_size)`` of one whole motion, from rest, ``chunk`` frames at
        a time (no gradients). At each of ``restarts`` another motion starts and the GRU starts
        from rest again, as at a training crop's first frame: each run between them gets the
        codes it gets alone.

        Args:
            gamma: ``(T, descriptor_size)`` motion descriptor.
            betas: ``(betas_size,)`` body shape.
            chunk: frames per GRU call (bounds the memory of long sequences).
            restarts: frames (0 < k < T, increasing) where another motion starts
                (``motion_restarts``).
        """
        device = self.output.weight.device
        gamma = torch.as_tensor(gamma, dtype=torch.float32, device=device)
        betas = torch.as_tensor(betas, dtype=torch.float32, device=device)[None]
        out: list[torch.Tensor] = []
        for a, b in itertools.pairwise((0, *restarts, len(gamma))):
            state: State | None = None
            for part in gamma[a:b].split(max(1, int(chunk))):
                z, state = self(part[None], betas, state)
                out.append(z[0])
        if not out:
            return gamma.new_zeros((0, self.latent_size))
        return torch.cat(out)

    def config(self) -> dict[str, Any]:
        """The constructor's arguments (JSON-able): ``from_config(c)`` rebuilds the module."""
        return {
            "descriptor_size": self.descriptor_size,
            "hidden": list(self.hidden),
            "latent_size": self.latent_size,
            "betas_size": self.betas_size,
        }

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> GarmentRegressor:
        """An untrained regressor of the shape ``config`` describes (load a state dict into it;
        the normalisation buffers come with it)."""
        return cls(
            descriptor_size=int(config["descriptor_size"]),
            hidden=tuple(int(h) for h in config["hidden"]),
            latent_size=int(config["latent_size"]),
            betas_size=int(config.get("betas_size", NUM_BETAS)),
        )
