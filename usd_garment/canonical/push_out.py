"""Canonical garments pushed out of the canonical body: every vertex closer than ε to the body
(or inside it), by the baked canonical SDF, moved along the SDF's gradient to ε outside.

The learned method runs this on the decoder's output before posing: the networks are trained to
keep their garments out of the canonical body (L_collision), but on motions unlike their training
data some decoded vertices still land inside it, and posing carries them into the posed body. One
SDF lookup per vertex and a gradient for the few that are close: far cheaper than the posed
push-out (winding numbers against each posed frame), and it leaves the posed collisions that
posing itself makes (where it folds the cloth) to that one.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from usd_garment.generative.losses import COLLISION_EPSILON

#: Newton steps along the gradient (the trilinear grid SDF is not exactly a distance).
PASSES = 2
#: Bound on the grid SDF's slope, and a margin (m), for skipping vertices far from the body.
LIPSCHITZ = 1.5
MARGIN = 1e-3


def push_out_canonical(
    x: torch.Tensor,
    sdf: Callable[[torch.Tensor], torch.Tensor],
    epsilon: float = COLLISION_EPSILON,
    passes: int = PASSES,
) -> torch.Tensor:
    """Canonical garments ``x`` ``(B, N, 3)`` (m) with every vertex whose SDF is below
    ``epsilon`` (m) moved along the SDF gradient to SDF ≈ ``epsilon``; the other vertices are
    returned unchanged. ``sdf``: points ``(..., 3)`` → signed distances ``(...)`` (m, negative
    inside), differentiable (``BodyFields.sdf``).

    The SDF is looked up once at the garments' mean ``(N, 3)``; a vertex is only looked up again
    where that value, less its distance from the mean (with a margin: the grid's SDF is nearly
    1-Lipschitz), could be below ``epsilon``: most of a chunk of frames is skipped."""
    out = x.detach().clone()
    with torch.no_grad():
        mean = out.mean(dim=0)
        bound = sdf(mean)[None] - LIPSCHITZ * (out - mean).norm(dim=-1)  # (B, N), m
        candidates = (bound < epsilon + MARGIN).view(-1).nonzero().squeeze(1)
    flat = out.view(-1, 3)
    for _ in range(passes):
        if candidates.numel() == 0:
            break
        with torch.no_grad():  # the candidates' values first: few of them need a gradient
            near = sdf(flat[candidates]) < epsilon
        if not bool(near.any()):
            break
        candidates = candidates[near]
        d, normal = sdf_and_normal(sdf, flat[candidates])
        flat[candidates] += (epsilon - d).unsqueeze(-1) * normal
    return out


def sdf_and_normal(
    sdf: Callable[[torch.Tensor], torch.Tensor], points: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Signed distances ``(M,)`` (m) of points ``(M, 3)`` and the unit gradients ``(M, 3)`` of
    ``sdf`` there (the outward normal of the body's level set)."""
    with torch.enable_grad():
        p = points.detach().requires_grad_(True)
        d = sdf(p)
        (grad,) = torch.autograd.grad(d.sum(), p)
    return d.detach(), grad / grad.norm(dim=-1, keepdim=True).clamp_min(1e-12)
