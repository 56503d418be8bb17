"""Posed garments pushed out of the posed body through the body's skinning preimages, with no
search structure per frame (the learned method's "learned+preimage").

A posed point p lies inside the posed body where some canonical point q that the body's linear
blend skinning carries to p lies inside the canonical body (away from where the body intersects
itself). A garment vertex has its own preimage, its decoded canonical position X, which
``push_out_canonical`` keeps out of the canonical body. Its other preimages are where posing puts
it into another part: a sleeve carried into the chest by an arm lowered against the trunk. They
are searched per joint j: the rigid guess R_jᵀ(p − t_j) (the point in the rest frame of j's
bone), kept where it falls in the box of j's part of the rest body (the posed ball round the box
sorts out most vertices first) and away from the vertex's own preimage, then refined by
fixed-point steps of inverse skinning with the body's diffused fields (as the projection unposes
garments; a step that turns back on the one before is shortened). Guesses that converge on the
vertex's own preimage, or cannot end near the canonical body, are dropped after each step. A
refined guess that skins back to p is a preimage; where it lies less than ε outside the
canonical body (the baked SDF), p moves by the skinned normal until it is ε outside.

Shapes: T frames, N garment vertices, J = 24 joints, M candidate (frame, vertex) pairs of a
joint, K = 10 shape coefficients. Units: metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from usd_garment.body.lbs import inverse_skin
from usd_garment.body.model import BodyModel
from usd_garment.canonical.push_out import sdf_and_normal
from usd_garment.fields.body_fields import BodyFields

#: Margin (m) around each part's box in its bone's rest frame.
BOX_MARGIN = 0.01
#: A rigid guess nearer than this (m) to the vertex's own preimage is taken to be that one: the
#: bones around a vertex turn apart by a few degrees, which moves the rigid guesses of its own
#: preimage by up to a few centimetres.
OWN_DISTANCE = 0.04
#: Fixed-point steps of inverse skinning refining a rigid guess.
PREIMAGE_STEPS = 8
#: A step that turns back on the one before is shortened by this factor: where the skinning
#: weights turn fast (between two bones) the plain steps oscillate about the fixed point.
DAMPING = 0.5
#: A refined guess this near (m) to the vertex's own preimage after a step is converging on it.
OWN_RADIUS = 0.01
#: The fixed point is taken to lie at most this many times a step's length from where the step
#: began (steps that shrink by half or more each time).
STEP_BOUND = 2.0
#: A refined guess is a preimage where it skins to within this (m) of the vertex.
PREIMAGE_TOLERANCE = 1e-3
#: Passes over the joints; a later pass revisits only the vertices the one before moved (a move
#: out of one part can end inside a part checked before it, where the spine's parts meet).
PASSES = 2


@dataclass(frozen=True)
class PartBoxes:
    """Axis-aligned boxes ``(J, 3)`` (m) of each joint's part of the shaped rest body (the
    vertices whose largest skinning weight is that joint's), widened by a margin, in the rest
    frame; a joint that dominates no vertex gets an empty box."""

    lower: torch.Tensor
    upper: torch.Tensor

    @classmethod
    def of(cls, body: BodyModel, betas: torch.Tensor, margin: float = BOX_MARGIN) -> PartBoxes:
        """The boxes of ``body`` shaped by ``betas`` ``(K,)``."""
        with torch.no_grad():
            shaped, _ = body.shaped(betas[None].float())
        part = body.weights.argmax(dim=1)  # (V,)
        joints = body.weights.shape[1]
        lower = torch.full((joints, 3), float("inf"))
        upper = torch.full((joints, 3), float("-inf"))
        lower = lower.scatter_reduce(0, part[:, None].expand(-1, 3), shaped[0], "amin")
        upper = upper.scatter_reduce(0, part[:, None].expand(-1, 3), shaped[0], "amax")
        return cls(lower - margin, upper + margin)

    def parts(self) -> list[int]:
        """The joints whose box is not empty."""
        return torch.nonzero((self.lower <= self.upper).all(-1))[:, 0].tolist()

    def spheres(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Centres ``(J, 3)`` (m, rest frame) and radii ``(J,)`` (m) of the balls round the
        boxes."""
        return (self.lower + self.upper) / 2, (self.upper - self.lower).norm(dim=-1) / 2


def preimage_push(
    points: torch.Tensor,
    own: torch.Tensor,
    transforms: torch.Tensor,
    fields: BodyFields,
    betas: torch.Tensor,
    boxes: PartBoxes,
    epsilon: float,
) -> torch.Tensor:
    """Posed garments ``(T, N, 3)`` with every vertex that has another preimage less than
    ``epsilon`` outside the canonical body moved to ``epsilon`` outside (one move per joint,
    joints in order, in up to :data:`PASSES` passes).

    Args:
        points: ``(T, N, 3)`` posed garment vertices (m).
        own: ``(T, N, 3)`` their own preimages in the rest frame, X + B̃s(X)·β
            (``GarmentOutput.unposed``).
        transforms: ``(T, J, 4, 4)`` the body's skinning transforms (``Articulation``).
        fields: the body's diffused fields and canonical SDF (without pose blendshapes).
        betas: ``(K,)`` the body shape.
        boxes: ``PartBoxes.of(body, betas)``.
        epsilon: distance (m) outside the body the moved vertices end at.
    """
    out = points.clone()
    visit = torch.ones(points.shape[:2], dtype=torch.bool)  # (T, N): the vertices this pass sees
    with torch.no_grad():
        for _ in range(PASSES):
            moved = torch.zeros_like(visit)
            for j in boxes.parts():
                _push_part(out, own, transforms, fields, betas, boxes, epsilon, j, visit, moved)
            visit = moved
            if not bool(visit.any()):
                break
    return out


def _push_part(
    out: torch.Tensor,
    own: torch.Tensor,
    transforms: torch.Tensor,
    fields: BodyFields,
    betas: torch.Tensor,
    boxes: PartBoxes,
    epsilon: float,
    j: int,
    visit: torch.Tensor,
    moved: torch.Tensor,
) -> None:
    """One joint's step of :func:`preimage_push` on the vertices ``visit`` ``(T, N)`` of
    ``out`` ``(T, N, 3)``, in place; the vertices it moves are set in ``moved``."""
    bone = transforms[:, j]  # (T, 4, 4)
    centre, radius = (v[j] for v in boxes.spheres())
    posed = bone[:, :3, :3] @ centre + bone[:, :3, 3]  # (T, 3): the ball's centre, posed
    near = visit & ((out - posed[:, None]).square().sum(-1) < radius**2)
    frame, vertex = near.nonzero(as_tuple=True)
    target, mine = out[frame, vertex], own[frame, vertex]
    # (p - t) R, i.e. Rᵀ(p - t) for each point: the rigid guess in j's rest frame.
    guess = torch.einsum("mc,mcd->md", target - bone[frame, :3, 3], bone[frame, :3, :3])
    keep = ((guess > boxes.lower[j]) & (guess < boxes.upper[j])).all(-1)
    keep &= (guess - mine).square().sum(-1) > OWN_DISTANCE**2
    frame, vertex, guess, target, mine = (v[keep] for v in (frame, vertex, guess, target, mine))
    if frame.numel() == 0:
        return
    frames = transforms[frame]  # (M, J, 4, 4)
    x, weights, kept = _refine(guess, target, frames, mine, fields, betas, epsilon)
    if kept.numel() == 0:
        return
    distance, normal = sdf_and_normal(fields.sdf, x)
    hit = distance < epsilon
    if not bool(hit.any()):
        return
    chosen = kept[hit]
    frame, vertex = frame[chosen], vertex[chosen]
    blend = torch.einsum("mj,mjcd->mcd", weights[hit], frames[chosen, :, :3, :3])
    move = torch.einsum("mcd,md->mc", blend, normal[hit])
    out[frame, vertex] += (epsilon - distance[hit])[:, None] * move
    moved[frame, vertex] = True


def _refine(
    x: torch.Tensor,
    target: torch.Tensor,
    frames: torch.Tensor,
    own: torch.Tensor,
    fields: BodyFields,
    betas: torch.Tensor,
    epsilon: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The canonical preimages that :data:`PREIMAGE_STEPS` fixed-point steps of inverse
    skinning (a step that turns back on the one before shortened by :data:`DAMPING`) find from
    the rigid guesses ``x`` ``(M, 3)`` (shaped rest frame) of the posed points ``target``
    ``(M, 3)`` (skinning transforms ``frames`` ``(M, J, 4, 4)``; ``own`` ``(M, 3)`` the points'
    own preimages, shaped): those ``(F, 3)`` that skin back to within
    :data:`PREIMAGE_TOLERANCE` and may lie less than ``epsilon`` outside the canonical body,
    their skinning weights ``(F, J)`` and their indices ``(F,)`` into the M guesses.

    After the first step a candidate is dropped where it comes within :data:`OWN_RADIUS` of its
    own preimage (the steps converge on that one) or where its SDF is more than ``epsilon``
    even :data:`STEP_BOUND` times its next step closer (the SDF is 1-Lipschitz, and the
    fixed point is about that far off), so later steps look up the fields for a few only.
    """
    x = x - fields.shaped(x, betas)[1]  # the rigid guess is in the shaped rest frame
    kept, last = torch.arange(x.shape[0]), torch.zeros_like(x)
    for step in range(PREIMAGE_STEPS + 1):
        weights, offset = fields.shaped(x, betas)
        delta = inverse_skin(target[:, None], weights[:, None], frames)[:, 0] - offset - x
        shift = delta.norm(dim=-1)
        if step == PREIMAGE_STEPS:
            break
        if step > 0:
            stay = (x + offset - own).norm(dim=-1) > OWN_RADIUS
            stay &= fields.sdf(x) - STEP_BOUND * shift < epsilon
            kept, x, delta, last = kept[stay], x[stay], delta[stay], last[stay]
            target, frames, own = target[stay], frames[stay], own[stay]
            if kept.numel() == 0:
                return x, weights[:0], kept
        x = x + torch.where((delta * last).sum(-1, keepdim=True) < 0, DAMPING, 1.0) * delta
        last = delta
    found = shift < PREIMAGE_TOLERANCE
    return x[found], weights[found], kept[found]
