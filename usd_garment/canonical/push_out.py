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
    floor: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Canonical garments ``x`` ``(B, N, 3)`` (m) with every vertex whose SDF is below
    ``epsilon`` (m) moved along the SDF gradient to SDF ≈ ``epsilon``; the other vertices are
    returned unchanged. ``sdf``: points ``(..., 3)`` → signed distances ``(...)`` (m, negative
    inside), differentiable (``BodyFields.sdf``).

    A vertex is only looked up where a lower bound on its SDF could be below ``epsilon`` (with
    a margin): ``floor`` ``(B, N)`` (m) where the caller knows one, else the SDF at the
    garments' mean ``(N, 3)`` less the vertex's distance from it (the grid's SDF is nearly
    1-Lipschitz): most of a chunk of frames is skipped.

    Returns:
        The pushed garments ``(B, N, 3)`` and a lower bound ``(B, N)`` (m) on each one's SDF,
        for a later push of points near them: the value looked up, ``epsilon`` for a moved
        vertex (to the Newton steps' accuracy), else the bound it was skipped by.
    """
    out = x.detach().clone()
    with torch.no_grad():
        if floor is None:
            mean = out.mean(dim=0)
            floor = sdf(mean)[None] - LIPSCHITZ * (out - mean).norm(dim=-1)  # (B, N), m
        else:
            floor = floor.clone()  # the caller's is left as it was
        candidates = (floor < epsilon + MARGIN).view(-1).nonzero().squeeze(1)
    flat, known = out.view(-1, 3), floor.view(-1)
    for _ in range(passes):
        if candidates.numel() == 0:
            break
        with torch.no_grad():  # the candidates' values first: few of them need a gradient
            values = sdf(flat[candidates])
            known[candidates] = values
            near = values < epsilon
        if not bool(near.any()):
            break
        candidates = candidates[near]
        d, normal = sdf_and_normal(sdf, flat[candidates])
        flat[candidates] += (epsilon - d).unsqueeze(-1) * normal
        known[candidates] = epsilon
    return out, floor


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
