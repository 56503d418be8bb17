"""Projection of simulated garments to the canonical space of the garment model (the paper's
Sec. 3.3): for each frame find X minimising

    E_rec + ω1 E_strain + ω2 E_collision
    E_rec       = Σ_v ‖M_sim,v − M_G(X, β, θ)_v‖²                       (m²)
    E_strain    = Σ_t ‖½(F_tᵀF_t − I)‖²_F, F of T_G(X, β, θ) vs the template   (1)
    E_collision = Σ_v max(ε − SDF(X_v), 0)                                (m)

How it is solved (CPU throughput first). Frames go in chunks of ``chunk`` frames, every frame of
a chunk starting from the last solved frame (for the first chunk, the template draped on the
rest body when given), as the paper warm-starts from the previous frame. Two stages, both
batched over the chunk:

1. Fixed-point inverse skinning, X ← W(·, W̃(X))⁻¹(M_sim) − (T_G(X) − X), the fields frozen at
   the current X; a vertex keeps its X when a step raises its error. Forward passes only; it
   drives E_rec to ~0 for most vertices in a few steps.
2. L-BFGS (strong Wolfe line search) on the full objective, over the active vertices only: those
   within ε + ``active_margin`` of the canonical body or still off target by more than
   ``active_residual``, in any frame of the chunk, and their 1-ring. The others already sit at
   E_rec = 0 and E_collision = 0; only their share of the (tiny) strain term is left out.
   L-BFGS rather than Adam: from a near-optimal start Adam's fixed-size steps jitter (in a
   synthetic test it raised the mean reprojection error from 0.01 to 0.3 mm); L-BFGS converges.

Weights. E_rec is about 1e-6 m² per vertex for a 1 mm residual. ω2 = 0.1 m: the collision
hinge pushes with a constant force ω2 while the data term pulls back with 2·residual, so the
hinge wins for any vertex whose reprojection target lies less than ω2 / 2 = 5 cm inside the
ε-shell of the canonical body (an exact penalty: in effect a hard constraint). ω1 = 1e-5 m²
(the first default): a triangle strained by 0.1 (10 %) pulls its corners with about the force of
a 0.5 mm residual on a 2 cm triangle, so the strain term was meant to decide only where the data
term does not (vertices pushed out by the collision term and their neighbours). Measured on real
motion it does more: where posing folds the cloth (an arm against the trunk, hips flexed) X must
be strained far more than 10 % for M_G(X) to reach the simulation, and ω1 = 1e-5 holds such
vertices up to 5 cm off their targets, into the posed body (``usd-garment dataset floor``;
``docs/canonical.md``). The default is therefore ω1 = 1e-6 m²: a third fewer posed-back targets
inside the body, at the price of a rougher canonical garment where posing folds it.
ε = 2 mm: the push-out margin of the baselines (the simulated cloth itself rests about 4 mm out,
the simulator's contact radius).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from usd_garment.body.lbs import unskin_blended
from usd_garment.canonical.strain import TriangleStrain
from usd_garment.garment.model import Articulation, GarmentModel

#: Called with the number of frames finished so far.
Progress = Callable[[int], None]


@dataclass(frozen=True)
class ProjectionSettings:
    """Parameters of :func:`project_sequence`.

    Attributes:
        iterations: most L-BFGS iterations per chunk of frames.
        inverse_steps: fixed-point inverse-skinning steps before L-BFGS.
        strain_weight: ω1 (m²).
        collision_weight: ω2 (m).
        epsilon: ε, the margin outside the canonical body (m).
        chunk: frames optimised jointly.
        active_margin: vertices closer than ε + this to the canonical body are optimised (m).
        active_residual: vertices off their target by more than this after inverse skinning
            are optimised (m).
    """

    iterations: int = 20
    inverse_steps: int = 8
    strain_weight: float = 1e-6
    collision_weight: float = 0.1
    epsilon: float = 2e-3
    chunk: int = 4
    active_margin: float = 1e-3
    active_residual: float = 1e-4

    def to_json(self) -> dict[str, float | int]:
        return dict(self.__dict__)


@dataclass
class Projection:
    """Result of :func:`project_sequence`.

    Attributes:
        canonical: ``(T, N, 3)`` float32 canonical garment X per frame (m).
        error: ``(T,)`` mean per-vertex distance ‖M_sim − M_G(X)‖ per frame (m).
        max_error: ``(T,)`` largest per-vertex distance per frame (m).
        seconds: wall time of the projection (s).
    """

    canonical: np.ndarray
    error: np.ndarray
    max_error: np.ndarray
    seconds: float


def project_sequence(
    model: GarmentModel,
    template: np.ndarray,
    faces: np.ndarray,
    points: np.ndarray,
    betas: np.ndarray,
    pose: np.ndarray,
    trans: np.ndarray,
    settings: ProjectionSettings | None = None,
    progress: Progress | None = None,
    start: np.ndarray | None = None,
) -> Projection:
    """Canonical X of every frame of a simulated garment sequence.

    Args:
        model: the garment model M_G (body, diffused fields and canonical SDF).
        template: ``(N, 3)`` garment template (m): the rest triangles of E_strain.
        faces: ``(F, 3)`` garment triangles.
        points: ``(T, N, 3)`` simulated garment, posed (m, canonical frame: Y-up).
        betas: ``(10,)`` or ``(T, 10)`` body shape.
        pose: ``(T, 24, 3)`` axis-angle pose (rad).
        trans: ``(T, 3)`` root translation (m).
        settings: solver parameters; ``ProjectionSettings()`` by default.
        progress: called with the number of frames done after each chunk.
        start: ``(N, 3)`` where the first frame's optimisation starts (m): the template draped on
            the rest body, as in the paper; ``template`` by default.

    Raises:
        ValueError: inconsistent shapes or non-finite input.
    """
    settings = settings or ProjectionSettings()
    points = np.asarray(points)
    t_frames, n = points.shape[0], template.shape[0]
    if points.ndim != 3 or points.shape[1:] != (n, 3):
        raise ValueError(f"points must be (T, {n}, 3) for this template, got {points.shape}")
    if pose.shape != (t_frames, 24, 3) or trans.shape != (t_frames, 3):
        raise ValueError(f"pose must be ({t_frames}, 24, 3) and trans ({t_frames}, 3)")
    if start is not None and np.shape(start) != (n, 3):
        raise ValueError(f"start must be ({n}, 3), got {np.shape(start)}")
    if not np.isfinite(points).all():
        raise ValueError("the simulated points contain NaN or infinity")
    device = model.body.v_template.device
    f32 = {"dtype": torch.float32, "device": device}
    rest = torch.as_tensor(template, **f32)
    faces_t = torch.as_tensor(faces, dtype=torch.int64, device=device)
    betas_all = torch.as_tensor(np.broadcast_to(betas, (t_frames, 10)).copy(), **f32)
    start_x = rest if start is None else torch.as_tensor(start, **f32)
    canonical = np.empty((t_frames, n, 3), dtype=np.float32)
    error = np.empty(t_frames)
    max_error = np.empty(t_frames)
    started = time.perf_counter()
    for s in range(0, t_frames, settings.chunk):
        e = min(s + settings.chunk, t_frames)
        target = torch.as_tensor(points[s:e], **f32)
        with torch.no_grad():
            art = model.articulation(
                betas_all[s:e],
                torch.as_tensor(pose[s:e], **f32),
                torch.as_tensor(trans[s:e], **f32),
            )
        x = _inverse_skinning(model, art, target, start_x.expand(e - s, -1, -1), settings)
        x = _refine(model, art, target, x, rest, faces_t, settings)
        with torch.no_grad():
            dist = (model.pose(x, art).vertices - target).norm(dim=-1)
        canonical[s:e] = x.cpu().numpy()
        error[s:e] = dist.mean(-1).cpu().numpy()
        max_error[s:e] = dist.amax(-1).cpu().numpy()
        start_x = x[-1]
        if progress is not None:
            progress(e)
    return Projection(canonical, error, max_error, time.perf_counter() - started)


def _inverse_skinning(
    model: GarmentModel,
    art: Articulation,
    target: torch.Tensor,
    x: torch.Tensor,
    settings: ProjectionSettings,
) -> torch.Tensor:
    """Fixed-point steps X ← skin⁻¹(target; W̃(X)) − (T_G(X) − X): solves E_rec = 0 with the
    fields frozen at the current X; a vertex keeps its old X when the step raises its error."""
    with torch.no_grad():
        out = model.pose(x, art)
        unposed, blended = out.unposed, out.blended
        err = (out.vertices - target).square().sum(-1)
        for _ in range(settings.inverse_steps):
            step = unskin_blended(target, blended) - (unposed - x)
            new = model.pose(step, art)
            new_err = (new.vertices - target).square().sum(-1)
            better = (new_err < err)[..., None]
            x = torch.where(better, step, x)
            err = torch.minimum(new_err, err)
            unposed = torch.where(better, new.unposed, unposed)
            blended = torch.where(better[..., None], new.blended, blended)
    return x


def _active_vertices(
    model: GarmentModel,
    art: Articulation,
    target: torch.Tensor,
    x: torch.Tensor,
    faces: torch.Tensor,
    settings: ProjectionSettings,
) -> torch.Tensor:
    """Indices ``(M,)`` of the vertices the optimiser moves: in any frame of the chunk within
    ``epsilon + active_margin`` of the canonical body or off their target by more than
    ``active_residual``, and the vertices sharing a triangle with them."""
    with torch.no_grad():
        residual = (model.pose(x, art).vertices - target).norm(dim=-1)
        near = model.fields.sdf(x) < settings.epsilon + settings.active_margin
        seed = (near | (residual > settings.active_residual)).any(0)  # (N,)
        ring = seed[faces].any(-1)  # triangles touching a seed vertex
        active = seed.clone()
        active[faces[ring].reshape(-1)] = True
    return active.nonzero().squeeze(1)


def _refine(
    model: GarmentModel,
    art: Articulation,
    target: torch.Tensor,
    x: torch.Tensor,
    template: torch.Tensor,
    faces: torch.Tensor,
    settings: ProjectionSettings,
) -> torch.Tensor:
    """L-BFGS on E_rec + ω1 E_strain + ω2 E_collision, summed over the chunk's frames, over the
    active vertices (:func:`_active_vertices`); the others stay at their inverse-skinning X,
    where E_rec = 0 and E_collision = 0 already, so only their (tiny) strain terms are left out.
    """
    active = _active_vertices(model, art, target, x, faces, settings)
    if settings.iterations == 0 or active.numel() == 0:
        return x
    # Triangles with an active corner, re-indexed into [active vertices, fixed corners].
    touched = torch.isin(faces, active).any(-1)
    sub_faces = faces[touched]
    corners = torch.unique(sub_faces)
    fixed = corners[~torch.isin(corners, active)]
    order = torch.cat([active, fixed])
    remap = torch.full((x.shape[1],), -1, dtype=torch.int64, device=x.device)
    remap[order] = torch.arange(order.numel(), device=x.device)
    strain = TriangleStrain(template[order], remap[sub_faces])
    with torch.no_grad():
        fixed_unposed = model.pose(x[:, fixed], art).unposed
    sub_target = target[:, active]
    x_active = x[:, active].clone().requires_grad_(True)
    optimiser = torch.optim.LBFGS(
        [x_active], lr=1.0, max_iter=settings.iterations, history_size=10,
        line_search_fn="strong_wolfe", tolerance_grad=1e-10, tolerance_change=1e-14,
    )  # fmt: skip

    def closure() -> torch.Tensor:
        optimiser.zero_grad(set_to_none=True)
        loss = objective(model, art, sub_target, x_active, strain, settings, fixed_unposed).sum()
        loss.backward()
        return loss

    optimiser.step(closure)
    x = x.clone()
    x[:, active] = x_active.detach()
    return x


def objective(
    model: GarmentModel,
    art: Articulation,
    target: torch.Tensor,
    x: torch.Tensor,
    strain: TriangleStrain,
    settings: ProjectionSettings,
    fixed_unposed: torch.Tensor | None = None,
) -> torch.Tensor:
    """E_rec + ω1 E_strain + ω2 E_collision per frame ``(B,)`` for X ``(B, M, 3)`` and its
    targets ``(B, M, 3)``; ``strain``'s mesh has these M vertices first, then the vertices
    ``fixed_unposed`` ``(B, K, 3)`` (T_G of vertices held fixed), if any."""
    out = model.pose(x, art)
    e_rec = (out.vertices - target).square().sum((-1, -2))
    unposed = out.unposed if fixed_unposed is None else torch.cat([out.unposed, fixed_unposed], 1)
    e_strain = strain.energy(unposed)
    e_collision = (settings.epsilon - model.fields.sdf(x)).clamp_min(0.0).sum(-1)
    return e_rec + settings.strain_weight * e_strain + settings.collision_weight * e_collision
