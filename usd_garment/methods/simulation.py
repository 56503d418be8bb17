"""The physics baseline and training-data maker as a garment method: the garment simulated with
Newton's Style3D cloth (``usd_garment.sim``) on the animated body, starting from the draped
template graded to the body's shape on the shaped T-pose body, with every frame checked (NaN,
inside the body where the pose does not force it, far from it, stretch).
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, replace
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from usd_garment.body.joints import NUM_JOINTS
from usd_garment.body.lbs import blend_shapes
from usd_garment.body.model import BodyModel
from usd_garment.garment.library import find_draped
from usd_garment.garment.template import GarmentTemplate
from usd_garment.methods.base import Progress
from usd_garment.methods.lbs import nearest_body_vertex
from usd_garment.motion.cuts import motion_cuts, motion_restarts
from usd_garment.motion.jumps import jump_maps, mapped, root_jumps, without_jumps
from usd_garment.motion.sequence import SmplMotion
from usd_garment.sim.checks import CheckLimits
from usd_garment.sim.cloth import (
    ITERATIONS,
    MAX_BAD_RUN,
    MAX_SUBSTEPS,
    SUBSTEPS,
    ContactRelease,
    ContactSettings,
    SimResult,
    easing,
    simulate_sequence,
)
from usd_garment.sim.drape import drape_template
from usd_garment.sim.material import ClothMaterial

#: Frames easing the body from the rest pose and shape into the motion's first frame.
LEAD_IN_FRAMES = 15
#: Frames holding the first frame before the motion plays.
SETTLE_FRAMES = 5
#: Frames skinned at once when posing the body (bounds memory).
FRAMES_PER_CHUNK = 64
#: Rest-body vertices whose shape blendshapes a garment vertex averages when graded to a shape.
GRADING_NEIGHBOURS = 8


#: Joints (SMPL order) whose skin becomes a collider of its own (see ``collider_parts``): each
#: arm from the shoulder down and each leg from the hip down; the rest is the trunk.
COLLIDER_PARTS: dict[str, tuple[int, ...]] = {
    "left arm": (16, 18, 20, 22),
    "right arm": (17, 19, 21, 23),
    "left leg": (1, 4, 7, 10),
    "right leg": (2, 5, 8, 11),
}


class SimulationError(ValueError):
    """A sequence failed (NaN, a garment that fell off, a long run of bad frames, or with
    ``strict`` any frame failing its checks with the most substeps): nothing to write."""


def _newton_version() -> str:
    try:
        import newton
    except ImportError:  # pragma: no cover - depends on the installation
        return "not installed"
    return str(newton.__version__)


def _posed(body: BodyModel, betas: np.ndarray, pose: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """``(T, V, 3)`` float64 body vertices for betas ``(T, 10)`` or ``(10,)``, pose
    ``(T, 24, 3)`` and trans ``(T, 3)``, skinned in chunks."""
    out = np.empty((len(pose), body.num_vertices, 3), dtype=np.float64)
    betas_t = torch.as_tensor(np.asarray(betas), dtype=torch.float32)
    with torch.no_grad():
        for s in range(0, len(pose), FRAMES_PER_CHUNK):
            e = min(s + FRAMES_PER_CHUNK, len(pose))
            b = betas_t if betas_t.dim() == 1 else betas_t[s:e]
            posed = body(
                b,
                torch.as_tensor(pose[s:e], dtype=torch.float32),
                torch.as_tensor(trans[s:e], dtype=torch.float32),
            )
            out[s:e] = posed.vertices.double().numpy()
    return out


def shape_offsets(body: BodyModel, vertices: np.ndarray, betas: np.ndarray) -> np.ndarray:
    """``(N, 3)`` displacement (m) that grades garment rest vertices ``(N, 3)`` to body shape
    ``betas`` ``(10,)``: the shape blendshapes of the ``GRADING_NEIGHBOURS`` nearest vertices of
    the rest body (β = 0, T-pose), averaged with inverse-distance weights."""
    distance, index = cKDTree(body.v_template.numpy()).query(
        np.asarray(vertices, dtype=np.float64), k=GRADING_NEIGHBOURS
    )
    weights = 1.0 / np.maximum(distance, 1e-4)
    weights /= weights.sum(axis=1, keepdims=True)
    betas_t = torch.as_tensor(np.asarray(betas), dtype=torch.float32)[None]
    offsets = blend_shapes(betas_t, body.shapedirs[torch.from_numpy(index.reshape(-1))])
    return np.einsum("nk,nkc->nc", weights, offsets[0].double().numpy().reshape(*index.shape, 3))


def collider_parts(body: BodyModel) -> np.ndarray:
    """``(F,)`` int64 collider label of each body triangle: 0 for the trunk (and head), ``k``
    for the ``k``-th part of ``COLLIDER_PARTS``, by the joint with the largest skinning weight,
    taken by majority over the triangle's corners (the trunk on a three-way tie).

    Separate colliders let cloth pinched between an arm and the trunk (a gap narrower than two
    contact radii) feel both surfaces; one collider only pushes a vertex away from its closest
    surface, into the other.
    """
    joint = body.weights.numpy().argmax(axis=1)
    vertex_part = np.zeros(body.num_vertices, dtype=np.int64)
    for k, joints in enumerate(COLLIDER_PARTS.values(), start=1):
        vertex_part[np.isin(joint, joints)] = k
    corners = vertex_part[body.faces.numpy()]  # (F, 3)
    majority = np.where(corners[:, 1] == corners[:, 2], corners[:, 1], corners[:, 0])
    return np.where((corners[:, 0] == corners[:, 1]) | (corners[:, 0] == corners[:, 2]) |
                    (corners[:, 1] == corners[:, 2]), majority, 0)  # fmt: skip


def arm_release(body: BodyModel, template: GarmentTemplate) -> ContactRelease:
    """The contacts ``ContactSettings.release`` drops: the garment's torso particles (``(N,)``,
    those whose nearest rest-body vertex is not an arm's, by the joint with the largest skinning
    weight; nearly all of a sleeveless dress's) against the arms' skin (``(Vb,)``,
    the vertices of the arm parts of ``COLLIDER_PARTS``, shoulder to hand)."""
    joint = body.weights.numpy().argmax(axis=1)
    arm = np.isin(joint, COLLIDER_PARTS["left arm"] + COLLIDER_PARTS["right arm"])
    return ContactRelease(~arm[nearest_body_vertex(body, template)], arm)


def lead_in_bodies(
    body: BodyModel, motion: SmplMotion, count: int, settle: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The motion's body shape in the T-pose, and ``count + settle`` frames bringing it into the
    motion's first frame: the pose interpolated with a smoothstep over ``count`` frames, then
    held for ``settle`` (the shape held throughout), skinned.

    The root comes up to the motion's first velocity on the way (:func:`root_glide`), so that
    the cloth moves with the body when the motion begins: a capture that starts mid-run would
    otherwise take the body from rest to running speed within one frame, and the cloth, left
    behind, falls off (CMU 09_01 starts at 3.3 m/s).

    Returns:
        ``(V, 3)`` rest body (the motion's β, T-pose, where the glide starts), ``(count +
        settle, V, 3)`` frames (the motion's first frame follows the last one) and ``(3,)`` the
        root's position in the rest body (m).
    """
    w = easing(count)[:, None, None]
    first = np.asarray(motion.pose[:1], dtype=np.float64)
    pose = np.concatenate([w * first, np.repeat(first, settle, axis=0)])
    trans = root_glide(np.asarray(motion.trans, dtype=np.float64), motion.fps, count + settle)
    betas = np.asarray(motion.betas, dtype=np.float64)
    rest = _posed(body, betas, np.zeros((1, NUM_JOINTS, 3)), trans[:1])[0]
    return rest, _posed(body, betas, pose, trans[1:]), trans[0]


def root_glide(trans: np.ndarray, fps: float, steps: int) -> np.ndarray:
    """``(steps + 1, 3)`` root positions (m) before a motion whose root positions are ``trans``
    ``(T, 3)`` at ``fps``: from rest, the velocity rises along a smoothstep to the motion's
    first one, (trans[1] − trans[0])·fps (zero for a single frame), and the motion's first
    frame would be the next position, ``trans[0]``. Positions 0 and 1..steps are the rest body
    and the warm-up frames."""
    velocity = (trans[1] - trans[0]) * fps if len(trans) > 1 else np.zeros(3)
    ramp = easing(steps + 1)  # the steps into positions 1..steps + 1
    behind = np.cumsum(ramp[::-1])[::-1] / fps  # (steps + 1,) s at full speed to go
    return trans[0] - behind[:, None] * velocity


class SimulationMethod:
    """Newton Style3D cloth simulation of the garment on the animated body.

    The garment's rest geometry is the template graded to the motion's body shape (see
    ``shape_offsets``: a garment of the wearer's size); it starts from the draped template (the
    committed or cached one for this body, else draped on the spot) graded by the same offsets,
    on the motion's body shape in the T-pose, which eases into the first frame's pose over
    ``lead_in`` frames and holds it for ``settle`` frames, its root coming up to the motion's
    first velocity over both (:func:`lead_in_bodies`), then plays the motion; so again at each
    restart, where another motion starts (see :meth:`predict`). Frames that fail
    their checks even with ``max_substeps`` are kept and flagged (``strict``: the first one
    fails the sequence); NaN, a garment that fell off or more than ``max_bad_run`` bad frames
    in a row raise :class:`SimulationError`. After ``predict``, ``result`` holds the
    ``SimResult`` and ``settings`` the per-frame quality.
    """

    name = "simulation"
    version = "4"

    def __init__(
        self,
        substeps: int = SUBSTEPS,
        iterations: int = ITERATIONS,
        material: ClothMaterial | None = None,
        lead_in: int = LEAD_IN_FRAMES,
        settle: int = SETTLE_FRAMES,
        max_substeps: int = MAX_SUBSTEPS,
        start: GarmentTemplate | None = None,
        *,
        strict: bool = False,
        limits: CheckLimits | None = None,
        max_bad_run: int = MAX_BAD_RUN,
        contact: ContactSettings | None = None,
        split_colliders: bool = False,
    ) -> None:
        """Args: solver steps and iterations per frame, the fabric (cotton by default), lead-in
        and settle frames, the most substeps a retried frame may use, the start shape (default:
        the draped template), whether the first bad frame fails the sequence (``strict``), the
        frame checks' limits (by default ``CheckLimits.for_garment`` of the template), the most
        consecutive bad frames kept when not strict, the contact settings
        (``ContactSettings()`` by default) and whether the body is one collider per part
        (``collider_parts``) or a single one."""
        if substeps < 1 or iterations < 1 or lead_in < 0 or settle < 0 or max_bad_run < 0:
            raise ValueError(
                "substeps and iterations must be >= 1, lead-in, settle and max_bad_run >= 0"
            )
        if max_substeps < substeps:
            raise ValueError(f"max substeps ({max_substeps}) below substeps ({substeps})")
        self.substeps = substeps
        self.iterations = iterations
        self.material = material or ClothMaterial()
        self.lead_in = lead_in
        self.settle = settle
        self.max_substeps = max_substeps
        self.start = start
        self.strict = strict
        self.limits = limits
        self.garment_limits = CheckLimits()  # the last predicted garment's, when not given
        self.max_bad_run = max_bad_run
        self.contact = contact or ContactSettings()
        self.split_colliders = split_colliders
        self.start_source = ""
        self.result: SimResult | None = None

    @property
    def settings(self) -> dict[str, Any]:
        """Solver settings and, after ``predict``, the per-frame quality and worst check figures
        (JSON-ready; see ``result_summary``)."""
        out: dict[str, Any] = {
            "solver": "newton.SolverStyle3D",
            "version": self.version,
            "newton": _newton_version(),
            "substeps": self.substeps,
            "iterations": self.iterations,
            "max_substeps": self.max_substeps,
            "lead_in_frames": self.lead_in,
            "settle_frames": self.settle,
            "material": self.material.to_dict(),
            "rest_shape": f"template graded to the body shape ({GRADING_NEIGHBOURS} nearest "
            "rest-body vertices' shape blendshapes)",
            "start_shape": "draped template graded like the rest shape, on the shaped T-pose "
            "body; the lead-in eases the pose, the root comes up to the motion's first velocity",
            "contact": asdict(self.contact),
            "colliders": "trunk, " + ", ".join(COLLIDER_PARTS)
            if self.split_colliders
            else "whole body",
            "limits": asdict(self.limits or self.garment_limits),
            "strict": self.strict,
            "max_bad_run": self.max_bad_run,
        }
        if self.start_source:
            out["start"] = self.start_source
        if self.result is not None:
            out.update(result_summary(self.result, self.substeps))
        return out

    def predict(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        progress: Progress | None = None,
    ) -> np.ndarray:
        """Simulated garment points ``(T, N, 3)`` float32, canonical frame (m). Each run
        between the motion's restarts (``motion_restarts``: a splice of the joints, a declared
        cut, where another motion starts) is simulated from a lead-in of its own, as that
        motion alone would be; ``result`` joins the runs' (``SimResult.joined``). Across a jump
        of the root alone (``usd_garment.motion.jumps``) the body is simulated with the jump
        taken out and the garment put back after, so the cloth goes on as on the motion
        without the jump, moved; ``result`` holds the garment as simulated.

        Raises:
            SimulationError: a frame had NaNs or a vertex farther than the limits allow from
                the body, more than ``max_bad_run`` frames in a row failed their checks with
                ``max_substeps`` substeps, or (``strict``) any frame did.
        """
        start = self.start
        self.start_source = "given"
        if start is None:
            start = find_draped(template, body)
            self.start_source = "draped template"
        if start is None:
            start = drape_template(template, body, material=self.material).template
            self.start_source = "draped on the fly"
        if start.vertices.shape != template.vertices.shape:
            raise ValueError("the start shape and the template have different vertex counts")
        self.garment_limits = CheckLimits.for_garment(template.name)
        # Each run between restarts (where another motion starts) from its own lead-in, as a
        # motion of its own.
        restarts = motion_restarts(motion)
        cuts = motion_cuts(motion, restarts)
        runs: list[SimResult] = []
        points: list[np.ndarray] = []
        for a, b in itertools.pairwise((0, *restarts, motion.num_frames)):
            run = _frames(motion, a, b)
            inner = [k - a for k in cuts if a < k < b]  # jumps of the root alone only
            result, garment = self._run(run, inner, body, template, start, a, progress)
            runs.append(result)
            if not result.ok:
                break
            points.append(garment)
        self.result = runs[0] if len(runs) == 1 else SimResult.joined(runs)
        if not self.result.ok:
            raise SimulationError(f"simulation failed at {self.result.message}")
        return points[0] if len(points) == 1 else np.concatenate(points)

    def _run(
        self,
        motion: SmplMotion,
        cuts: list[int],
        body: BodyModel,
        template: GarmentTemplate,
        start: GarmentTemplate,
        first: int,
        progress: Progress | None,
    ) -> tuple[SimResult, np.ndarray]:
        """One run of a motion with no restart in it (its frames ``first`` on), simulated from
        the lead-in: its result and its garment ``(T, N, 3)`` float32 (m). A jump of the root
        alone among its ``cuts`` (a teleport within one motion) would leave the cloth behind:
        the body is simulated without it, and the garment moved back with it after."""
        jumps = root_jumps(motion, body, cuts, ())
        motion = without_jumps(motion, jumps, body)
        rest, lead, root = lead_in_bodies(body, motion, self.lead_in, self.settle)
        frames = _posed(body, motion.betas, motion.pose, motion.trans)
        warmup = self.lead_in + self.settle

        def report(done: int, total: int) -> None:
            if progress is not None and done > warmup:
                progress(first + done - warmup)

        # The rest shape and the start are graded by the same per-vertex offsets, so the draped
        # start on the shaped T-pose body matches the graded rest lengths from the first frame.
        offsets = shape_offsets(body, template.vertices, motion.betas)
        graded = template.vertices + offsets
        initial = np.asarray(start.vertices, np.float64) + offsets + root
        result = simulate_sequence(
            graded,
            template.faces,
            body.faces.numpy(),
            frames,
            body_rest=rest,
            lead_in=lead,  # the settle frames included
            settle_frames=0,
            material=self.material,
            substeps=self.substeps,
            iterations=self.iterations,
            fps=motion.fps,
            max_substeps=self.max_substeps,
            contact=self.contact,
            limits=self.limits or self.garment_limits,
            strict=self.strict,
            max_bad_run=self.max_bad_run,
            progress=report,
            initial_vertices=initial,
            body_parts=collider_parts(body) if self.split_colliders else None,
            release=arm_release(body, template),
            first_frame=first,
        )
        if not result.ok or not jumps:
            return result, result.points
        back = np.linalg.inv(jump_maps(motion.num_frames, jumps))
        return result, mapped(back, result.points).astype(np.float32)


def _frames(motion: SmplMotion, start: int, stop: int) -> SmplMotion:
    """The frames ``start`` to ``stop`` of ``motion`` as a motion of their own (``motion``
    itself where that is all of it), with no declared cut."""
    if start == 0 and stop == motion.num_frames:
        return motion
    return replace(
        motion, pose=motion.pose[start:stop], trans=motion.trans[start:stop],
        time_codes=motion.time_codes[start:stop], cut_times=(),
    )  # fmt: skip


def _rounded(values: list[float], digits: int) -> list[float | None]:
    """``values`` rounded to ``digits`` decimals, non-finite ones as None (valid JSON)."""
    return [round(float(v), digits) if np.isfinite(v) else None for v in values]


def _reduce(values: list[float], reduce: Any) -> float | None:
    """``reduce`` (e.g. ``max``, ``np.mean``) of the finite ``values``; None when there are none."""
    finite = [float(v) for v in values if np.isfinite(v)]
    return float(reduce(finite)) if finite else None


def result_summary(result: SimResult, substeps: int) -> dict[str, Any]:
    """The quality of a simulated sequence, JSON-ready and compact.

    Keys: ``status``, ``message``; ``retries`` (motion frame → substep doublings, frames without
    any left out); ``seconds_per_frame``; ``nan_frames``; ``bad_frames`` and
    ``lead_in_bad_frames`` (frames kept although they failed their checks); ``released_frames``
    (motion frames whose kept try dropped the torso's contacts with arm skin,
    ``ContactSettings.release``); the worst figures
    over the motion frames: ``inside_share_mean/max`` (inside the body, forced or not),
    ``inside_forced_share_mean/max``, ``inside_elsewhere_share_mean/max``,
    ``penetrating_share_max`` (inside-elsewhere deeper than the limit's depth),
    ``max_distance_m``, ``stretch_p99_max``, ``stretch_max`` (the single most stretched edge:
    a vertex snagged on a limb shows there, not in the p99), ``projected_share_mean/max``
    (vertices the end-of-frame projection moved out of the body); the lead-in's
    ``lead_in_stretch_p99_first`` and ``lead_in_stretch_p99_max``; and ``per_frame``, lists over
    the motion frames (shares as fractions rounded to 6 decimals, distances in m to 4, stretch
    to 4; None where NaN): ``inside_forced``, ``inside_elsewhere``, ``penetrating``,
    ``max_distance_m``, ``stretch_p99``, ``stretch_max``, ``projected``, ``substeps`` (used,
    after retries), ``bad`` and ``released`` (0/1).
    """
    checks = result.checks
    retries = {
        str(i): int(np.log2(used // substeps)) for i, used in enumerate(result.substeps)
        if used > substeps
    }  # fmt: skip
    forced = [c.inside_forced_share for c in checks]
    elsewhere = [c.inside_elsewhere_share for c in checks]
    inside = [c.inside_share for c in checks]
    lead = [c.stretch_p99 for c in result.lead_in_checks]
    return {
        "status": result.status,
        "message": result.message,
        "retries": retries,
        "seconds_per_frame": result.seconds_per_frame,
        "nan_frames": sum(1 for c in checks if c.nan_count),
        "bad_frames": int(sum(result.bad)),
        "released_frames": int(sum(result.released)),
        "lead_in_bad_frames": int(sum(result.lead_in_bad)),
        "inside_share_mean": _reduce(inside, np.mean),
        "inside_share_max": _reduce(inside, max),
        "inside_forced_share_mean": _reduce(forced, np.mean),
        "inside_forced_share_max": _reduce(forced, max),
        "inside_elsewhere_share_mean": _reduce(elsewhere, np.mean),
        "inside_elsewhere_share_max": _reduce(elsewhere, max),
        "penetrating_share_max": _reduce([c.penetrating_share for c in checks], max),
        "max_distance_m": _reduce([c.max_distance for c in checks], max),
        "stretch_p99_max": _reduce([c.stretch_p99 for c in checks], max),
        "stretch_max": _reduce([c.stretch_max for c in checks], max),
        "projected_share_mean": _reduce(result.projected, np.mean),
        "projected_share_max": _reduce(result.projected, max),
        "lead_in_stretch_p99_first": _reduce(lead[:1], max),
        "lead_in_stretch_p99_max": _reduce(lead, max),
        "per_frame": {
            "inside_forced": _rounded(forced, 6),
            "inside_elsewhere": _rounded(elsewhere, 6),
            "penetrating": _rounded([c.penetrating_share for c in checks], 6),
            "max_distance_m": _rounded([c.max_distance for c in checks], 4),
            "stretch_p99": _rounded([c.stretch_p99 for c in checks], 4),
            "stretch_max": _rounded([c.stretch_max for c in checks], 4),
            "projected": _rounded(result.projected, 6),
            "substeps": [int(n) for n in result.substeps],
            "bad": [int(b) for b in result.bad],
            "released": [int(r) for r in result.released],
        },
    }
