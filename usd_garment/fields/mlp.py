"""The fitter of the diffused fields: a 5×256 ReLU MLP per field, as in the paper's official code
(the skinning-weight field ends in a softmax over the 24 joints), trained on diffusion targets.

Shapes: M points ``(M, 3)`` in metres; C output channels (24 weights, 30 = 3 × 10 shape
blendshape entries or 621 = 3 × 207 pose blendshape entries).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

HIDDEN = 256
LAYERS = 5


class FieldMLP(torch.nn.Module):
    """``LAYERS`` hidden ReLU layers of ``HIDDEN`` units from a normalised point to C channels.

    Args:
        channels: C.
        softmax: end in a softmax (skinning weights) instead of an affine output.
        center: ``(3,)`` point mapped to the origin before the first layer (m).
        scale: length mapped to 1 (m).
        out_scale: ``(C,)`` per-channel scale of the affine output (targets' spread).
    """

    center: torch.Tensor
    scale: torch.Tensor
    out_scale: torch.Tensor

    def __init__(
        self,
        channels: int,
        softmax: bool,
        center: torch.Tensor | None = None,
        scale: float = 1.0,
        out_scale: torch.Tensor | None = None,
    ) -> None:
        super().__init__()
        layers: list[torch.nn.Module] = []
        width = 3
        for _ in range(LAYERS):
            layers += [torch.nn.Linear(width, HIDDEN), torch.nn.ReLU()]
            width = HIDDEN
        layers.append(torch.nn.Linear(width, channels))
        self.net = torch.nn.Sequential(*layers)
        self.softmax = softmax
        self.register_buffer("center", torch.zeros(3) if center is None else center.float())
        self.register_buffer("scale", torch.tensor(float(scale)))
        self.register_buffer(
            "out_scale", torch.ones(channels) if out_scale is None else out_scale.float()
        )

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Field values ``(M, C)`` at points ``(M, 3)``."""
        y = self.net((points - self.center) / self.scale)
        return torch.softmax(y, dim=-1) if self.softmax else y * self.out_scale

    @torch.no_grad()
    def evaluate(self, points: torch.Tensor, chunk: int = 65536) -> torch.Tensor:
        """``forward`` without gradients, in chunks of points."""
        return torch.cat([self(points[i : i + chunk]) for i in range(0, len(points), chunk)])


def train_field(
    mlp: FieldMLP,
    points: np.ndarray,
    targets: np.ndarray,
    *,
    epochs: int,
    batch: int = 4096,
    lr: float = 1e-3,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> float:
    """Fit ``mlp`` to ``targets`` ``(M, C)`` at ``points`` ``(M, 3)`` with Adam and a cosine
    learning-rate decay; L1 loss on the (softmax) weights, mean squared error relative to
    ``out_scale`` on blendshape entries. ``progress`` receives 1 per step.

    Returns:
        the mean loss of the last epoch.
    """
    gen = torch.Generator().manual_seed(seed)
    x = torch.as_tensor(points, dtype=torch.float32)
    y = torch.as_tensor(targets, dtype=torch.float32)
    steps_per_epoch = max(1, len(x) // batch)
    opt = torch.optim.Adam(mlp.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=epochs * steps_per_epoch)
    last = 0.0
    for _ in range(epochs):
        order = torch.randperm(len(x), generator=gen)
        total = 0.0
        for s in range(steps_per_epoch):
            idx = order[s * batch : (s + 1) * batch]
            pred = mlp(x[idx])
            if mlp.softmax:
                loss = (pred - y[idx]).abs().sum(-1).mean()
            else:
                loss = ((pred - y[idx]) / mlp.out_scale).square().mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach())
            if progress is not None:
                progress(1)
        last = total / steps_per_epoch
    return last
