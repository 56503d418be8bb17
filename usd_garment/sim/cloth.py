"""Physics simulation of a garment worn by an animated body, with NVIDIA Newton's Style3D cloth
solver: the training data of the generative garment model (numpy in, numpy out).

The body is one triangle mesh collider whose vertices are overwritten every substep, linearly
interpolated between the frames given. ``warp`` and ``newton`` (the ``[train]`` extra) are
imported when a simulator is built, not with this module.
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.eval.push_out import PUSH_OUT_EPS, push_out
from usd_garment.sim.checks import (
    CheckLimits,
    FrameCheck,
    edge_lengths,
    frame_body_distance,
    measure_frame,
    unique_edges,
)
from usd_garment.sim.material import ClothMaterial

#: Gravity along -Y (m/s²); our canonical frame is Y-up, metres.
GRAVITY = 9.81
#: Margin (m) around the body's broad-phase box.
AABB_PAD = 0.05
#: Default solver settings per 30 fps frame: substeps, and projective-dynamics iterations per
#: substep (4 iterations under-resolve the membrane: edge stretch p99 up to 1.3 in fast motions).
SUBSTEPS = 4
ITERATIONS = 10
#: Most substeps a failing frame is retried with (the substeps double on each retry).
MAX_SUBSTEPS = 16
#: Moves (m) below this are float rounding, not projections (``GarmentSimulator.project``).
MOVE_TOLERANCE = 1e-6
#: Most consecutive bad frames (failing their checks even with ``MAX_SUBSTEPS``) a sequence may
#: keep before it fails: a short run is a hard moment of the motion, a long one a lost garment.
MAX_BAD_RUN = 10
#: When the garment's released particles ignore the released skin (``ContactSettings.release``):
#: never, on one last try of a frame that fails its checks with the most substeps, or always.
RELEASE_MODES = ("never", "retry", "always")


@dataclass(frozen=True)
class ContactSettings:
    """Cloth-body and cloth-cloth contact parameters of the solver.

    Attributes:
        radius: particle radius (m); the cloth rests this far from the skin.
        gap: extra detection distance (m) beyond ``radius``: contacts are found only for
            vertices closer than ``radius + gap`` to the body surface, inside or out, so a
            vertex that gets deeper than ``gap`` into the body in one substep is lost.
        stiffness: penalty stiffness of the body contact (N/m per vertex).
        damping: damping of the body contact along its normal (N·s/m).
        self_radius: half-thickness of cloth-cloth contacts (m); Style3D's default is 3 mm.
        project: after each frame, move the vertices inside the body (where the pose does not
            force it) or closer than 2 mm to it out to 2 mm (``push_out``, the winding-number
            query) and drop their velocity against the move (an inelastic contact). The
            penalty contact alone leaves cloth pinched in gaps narrower than two contact radii
            (a hanging arm against the trunk) inside one part or the other.
        release: when the body contacts of a ``ContactRelease`` (the T-shirt's torso panels
            against arm skin) are dropped, one of ``RELEASE_MODES``: ``"retry"`` adds one last
            try, with the most substeps, to a frame that fails its checks with them. An arm
            pressed into the trunk, as captures hold it, catches the hem between its skin
            buried in the hip and the pelvis and tears it; released, the panels are kept out of
            the arm by the end-of-frame projection alone (where the arm is not forced into the
            trunk).
    """

    radius: float = 4e-3
    gap: float = 2e-2
    stiffness: float = 1e3
    damping: float = 1e-4
    self_radius: float = 3e-3
    project: bool = True
    release: str = "retry"

    def __post_init__(self) -> None:
        if self.release not in RELEASE_MODES:
            raise ValueError(f"release must be one of {RELEASE_MODES}, got {self.release!r}")


@dataclass(frozen=True)
class ContactRelease:
    """Body contacts that ``ContactSettings.release`` drops: those of the garment particles
    ``particles`` ``(N,)`` bool against the skin of the body vertices ``body_vertices``
    ``(Vb,)`` bool (a contact's body point belongs to its nearest posed body vertex)."""

    particles: np.ndarray
    body_vertices: np.ndarray


def _import_newton() -> tuple[Any, Any]:
    """``(warp, newton)``, with a clear error when the ``[train]`` extra is missing."""
    try:
        import newton
        import warp as wp
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError(
            "garment simulation needs NVIDIA Newton: pip install 'usd-garment[train]'"
        ) from exc
    wp.config.log_level = wp.LOG_WARNING  # no kernel-cache chatter: the library never prints
    return wp, newton


def panel_layout(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-triangle 2D rest shapes: each rest triangle flattened isometrically on its own.

    Style3D takes its rest geometry (lengths, areas, bending cotangents, mass) from a 2D panel
    layout. Flattening every triangle separately reproduces the 3D rest mesh exactly (a curved
    garment has no single isometric flattening). Each triangle's 2D frame has its ``v`` axis
    along world +Y projected onto the triangle (the warp runs down the garment, the weft around
    it); where the triangle faces up or down, along world +Z instead. The ``u`` axis completes a
    frame whose normal is the triangle's, so counter-clockwise triangles keep positive area.

    Args:
        vertices: ``(N, 3)`` rest positions (m).
        faces: ``(F, 3)`` triangles.

    Returns:
        ``(F, 3, 2)`` panel coordinates (m) of each triangle's corners, in the faces' order.
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    grain = np.where(np.abs(normal[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[0.0, 0.0, 1.0]])
    v_axis = grain - np.einsum("fi,fi->f", grain, normal)[:, None] * normal
    v_axis /= np.maximum(np.linalg.norm(v_axis, axis=1, keepdims=True), 1e-30)
    u_axis = np.cross(v_axis, normal)
    local = tri - tri[:, :1]
    return np.stack(
        [np.einsum("fki,fi->fk", local, u_axis), np.einsum("fki,fi->fk", local, v_axis)], axis=-1
    )


class GarmentSimulator:
    """One garment on one animated body, advanced one frame at a time.

    Style3D (projective dynamics, implicit Euler) with ``substeps`` steps of ``iterations``
    non-linear iterations per frame; gravity -9.81 m/s² along -Y. Contacts with the body are
    collected before each substep against the body interpolated to the end of that substep
    (without the ``release`` contacts while ``releasing`` is set).
    Warp runs CPU kernels on one thread: run one simulator per core.
    """

    def __init__(
        self,
        rest_vertices: np.ndarray,
        faces: np.ndarray,
        body_faces: np.ndarray,
        body_vertices0: np.ndarray,
        material: ClothMaterial | None = None,
        *,
        substeps: int = SUBSTEPS,
        iterations: int = ITERATIONS,
        fps: float = 30.0,
        contact: ContactSettings | None = None,
        initial_vertices: np.ndarray | None = None,
        body_parts: np.ndarray | None = None,
        release: ContactRelease | None = None,
        device: str = "cpu",
    ) -> None:
        """Build the Newton model.

        Args:
            rest_vertices: ``(N, 3)`` garment rest shape (m): defines rest lengths, areas, mass.
            faces: ``(F, 3)`` garment triangles, counter-clockwise seen from outside.
            body_faces: ``(Fb, 3)`` body triangles, counter-clockwise seen from outside.
            body_vertices0: ``(Vb, 3)`` body at the start (m).
            material: the fabric; SNUG's cotton by default.
            substeps: solver steps per frame.
            iterations: non-linear iterations per solver step.
            fps: frames per second of the body motion.
            contact: contact parameters; ``ContactSettings()`` by default.
            initial_vertices: ``(N, 3)`` garment start positions; ``rest_vertices`` by default.
            body_parts: ``(Fb,)`` integer part label of each body triangle: each part becomes
                its own collider, so a vertex between two parts (cloth pinched between an arm
                and the trunk) feels both; one collider for the whole body by default.
            release: the contacts that ``step`` drops while ``releasing`` is set.
            device: Warp device, ``"cpu"`` or e.g. ``"cuda:0"``.

        Raises:
            ValueError: arrays of the wrong shape or with non-finite values.
        """
        rest = _points(rest_vertices, "rest_vertices")
        faces = _faces(faces, len(rest), "faces")
        body0 = _points(body_vertices0, "body_vertices0")
        body_faces = _faces(body_faces, len(body0), "body_faces")
        start = rest if initial_vertices is None else _points(initial_vertices, "initial_vertices")
        if start.shape != rest.shape:
            raise ValueError(f"initial_vertices must be {rest.shape}, got {start.shape}")
        if substeps < 1 or iterations < 1 or not fps > 0:
            raise ValueError("substeps and iterations must be >= 1 and fps > 0")
        labels = np.zeros(len(body_faces), np.int64) if body_parts is None else body_parts
        labels = np.asarray(labels)
        if labels.shape != (len(body_faces),) or not np.issubdtype(labels.dtype, np.integer):
            raise ValueError(f"body_parts must be ({len(body_faces)},) integers")
        if release is not None and (
            np.shape(release.particles) != (len(rest),)
            or np.shape(release.body_vertices) != (len(body0),)
        ):
            raise ValueError(f"release masks must be ({len(rest)},) and ({len(body0)},)")

        wp, newton = _import_newton()
        from newton.solvers import SolverStyle3D, style3d

        self.material = material or ClothMaterial()
        self.contact = contact or ContactSettings()
        self.substeps = substeps
        self.iterations = iterations
        self.fps = float(fps)
        self.num_vertices = len(rest)
        self.surface = BodySurface(body_faces, len(body0))

        builder = newton.ModelBuilder(up_axis=newton.Axis.Y)
        SolverStyle3D.register_custom_attributes(builder)
        builder.default_edge_ke = self.material.solver_bending_stiffness
        k_stretch = self.material.stretch_stiffness
        style3d.add_cloth_mesh(
            builder,
            pos=wp.vec3(0.0, 0.0, 0.0),
            rot=wp.quat_identity(),
            vel=wp.vec3(0.0, 0.0, 0.0),
            vertices=start,
            indices=faces.ravel(),
            density=self.material.area_density,
            panel_verts=panel_layout(rest, faces).reshape(-1, 2),
            panel_indices=np.arange(3 * len(faces)),
            tri_aniso_ke=wp.vec3(k_stretch, k_stretch, self.material.shear_stiffness),
            particle_radius=self.contact.radius,
        )
        # The solver mixes the cloth's and the shape's friction as sqrt(mu_cloth * mu_shape).
        shape_cfg = newton.ModelBuilder.ShapeConfig(mu=self.material.friction)
        # One closed collider per body part: (shape index, its vertices, its Newton mesh).
        self._parts: list[tuple[int, _PartVertices, Any]] = []
        for label in np.unique(labels):
            part, part_faces = _closed_part(body_faces[labels == label])
            mesh = newton.Mesh(part.of(body0), part_faces.ravel(), compute_inertia=False)
            shape = builder.add_shape_mesh(body=-1, mesh=mesh, cfg=shape_cfg)
            self._parts.append((shape, part, mesh))
        self.model = builder.finalize(device=device)
        self.model.set_gravity((0.0, -GRAVITY, 0.0))
        self.model.soft_contact_ke = self.contact.stiffness
        self.model.soft_contact_kd = self.contact.damping
        self.model.soft_contact_mu = self.material.friction

        with contextlib.redirect_stdout(io.StringIO()):  # its set-up timer prints
            self.solver = SolverStyle3D(
                self.model, config=SolverStyle3D.Config(iterations=iterations)
            )
        self.solver.collision.radius = self.contact.self_radius
        self.pipeline = newton.CollisionPipeline(self.model, soft_contact_gap=self.contact.gap)
        self.contacts = self.pipeline.contacts()
        self.state_0 = self.model.state()
        self.state_1 = self.model.state()
        self.control = self.model.control()
        # The wp.Mesh of each part, which the collision pipeline queries.
        self._part_meshes = [(used, mesh.mesh) for _, used, mesh in self._parts]
        self.body_vertices = body0.copy()
        self.release = release
        #: Whether ``step`` drops the ``release`` contacts; set per frame by the caller.
        self.releasing = False
        #: Body contacts dropped so far (summed over substeps).
        self.released_contacts = 0

    @property
    def points(self) -> np.ndarray:
        """``(N, 3)`` float32 current garment vertices (m)."""
        return self.state_0.particle_q.numpy().copy()

    def body_distance(self) -> np.ndarray:
        """``(N,)`` signed distance (m, negative inside by winding number) of the current garment
        vertices to the body where the last ``step`` left it: the shared query of
        ``usd_garment.eval.body_distance``. The garment must be finite."""
        return frame_body_distance(self.points, self.body_vertices, self.surface)[0]

    def get_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A snapshot ``(points, velocities, body_vertices)`` to ``set_state`` back to."""
        return (
            self.state_0.particle_q.numpy().copy(),
            self.state_0.particle_qd.numpy().copy(),
            self.body_vertices.copy(),
        )

    def set_state(self, snapshot: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        """Restore a ``get_state`` snapshot (garment positions, velocities and the body)."""
        points, velocities, body = snapshot
        self.state_0.particle_q.assign(points)
        self.state_0.particle_qd.assign(velocities)
        self.body_vertices = body.copy()
        self._set_body(body, np.zeros_like(body))
        self._cover_body(body)

    def project(self, points: np.ndarray) -> None:
        """Move the garment vertices to ``points`` ``(N, 3)`` (m) between frames, as inelastic
        contacts: a vertex moved by more than ``MOVE_TOLERANCE`` keeps no velocity against its
        move."""
        before = self.state_0.particle_q.numpy().astype(np.float64)
        velocity = self.state_0.particle_qd.numpy().astype(np.float64)
        move = np.asarray(points, dtype=np.float64) - before
        length = np.linalg.norm(move, axis=1, keepdims=True)
        unit = np.divide(move, length, out=np.zeros_like(move), where=length > MOVE_TOLERANCE)
        velocity -= np.minimum((velocity * unit).sum(axis=1, keepdims=True), 0.0) * unit
        self.state_0.particle_q.assign(np.asarray(points, dtype=np.float32))
        self.state_0.particle_qd.assign(velocity.astype(np.float32))

    def _set_body(self, vertices: np.ndarray, velocities: np.ndarray) -> None:
        """Move the body colliders: overwrite their Warp meshes and refit the meshes' BVHs."""
        for part, mesh in self._part_meshes:
            mesh.points.assign(part.of(vertices).astype(np.float32))
            mesh.velocities.assign(part.of(velocities).astype(np.float32))
            mesh.refit()

    def _cover_body(self, *frames: np.ndarray) -> None:
        """Set the body shapes' broad-phase boxes (computed by Newton from the first vertices
        only) to cover the given body frames, so the broad phase never culls the moving body."""
        lower = self.model.shape_collision_aabb_lower.numpy()
        upper = self.model.shape_collision_aabb_upper.numpy()
        for shape, part, _ in self._parts:
            lower[shape] = np.min([f[part.used].min(axis=0) for f in frames], axis=0) - AABB_PAD
            upper[shape] = np.max([f[part.used].max(axis=0) for f in frames], axis=0) + AABB_PAD
        self.model.shape_collision_aabb_lower.assign(lower)
        self.model.shape_collision_aabb_upper.assign(upper)

    def step(self, body_vertices_next: np.ndarray) -> np.ndarray:
        """Advance one frame while the body moves linearly to ``body_vertices_next``.

        Args:
            body_vertices_next: ``(Vb, 3)`` body at the end of the frame (m).

        Returns:
            ``(N, 3)`` float32 garment vertices at the end of the frame (m).
        """
        target = np.asarray(body_vertices_next, dtype=np.float64)
        if target.shape != self.body_vertices.shape:
            raise ValueError(
                f"body vertices must be {self.body_vertices.shape}, got {target.shape}"
            )
        start = self.body_vertices
        velocity = (target - start) * self.fps
        dt = 1.0 / (self.fps * self.substeps)
        self._cover_body(start, target)
        for sub in range(self.substeps):
            alpha = (sub + 1) / self.substeps
            now = start + alpha * (target - start)
            self._set_body(now, velocity)
            self.pipeline.collide(self.state_0, self.contacts)
            if self.releasing and self.release is not None:
                self._drop_released(now)
            self.state_0.clear_forces()
            self.solver.step(self.state_0, self.state_1, self.control, self.contacts, dt)
            self.state_0, self.state_1 = self.state_1, self.state_0
        self.body_vertices = target
        return self.points

    def _drop_released(self, body: np.ndarray) -> None:
        """Drop the ``release`` contacts from the collision pipeline's body contacts (the
        rest are compacted to the front), the body at ``body`` ``(Vb, 3)`` (m)."""
        contacts = self.contacts
        count = min(int(contacts.soft_contact_count.numpy()[0]), contacts.soft_contact_max)
        particle = contacts.soft_contact_particle.numpy()[:count]
        candidates = np.flatnonzero(self.release.particles[particle])
        if candidates.size == 0:
            return
        points = contacts.soft_contact_body_pos.numpy()[candidates]
        nearest = cKDTree(body).query(points.astype(np.float64))[1]
        drop = candidates[self.release.body_vertices[nearest]]
        if drop.size == 0:
            return
        keep = np.setdiff1d(np.arange(count), drop)
        for array in (
            contacts.soft_contact_particle, contacts.soft_contact_shape,
            contacts.soft_contact_body_pos, contacts.soft_contact_body_vel,
            contacts.soft_contact_normal, contacts.soft_contact_indices,
            contacts.soft_contact_rigid_indices, contacts.soft_contact_barycentric,
        ):  # fmt: skip
            values = array.numpy()
            values[: len(keep)] = values[keep]
            array.assign(values)
        contacts.soft_contact_count.assign(np.array([len(keep)], dtype=np.int32))
        self.released_contacts += len(drop)


@dataclass(frozen=True)
class _PartVertices:
    """The vertices of one body part's collider: body vertices ``used`` ``(U,)``, then one
    vertex per hole of the part's surface at the centroid of the hole's rim (``rims``)."""

    used: np.ndarray
    rims: tuple[np.ndarray, ...]

    def of(self, body: np.ndarray) -> np.ndarray:
        """``(U + len(rims), 3)`` collider vertices of body vertices (or velocities)
        ``(Vb, 3)``."""
        caps = [body[rim].mean(axis=0) for rim in self.rims]
        return np.concatenate([body[self.used], np.reshape(caps, (-1, 3))])


def _closed_part(faces: np.ndarray) -> tuple[_PartVertices, np.ndarray]:
    """A body part's triangles ``(Fp, 3)`` (body vertex indices) closed by a fan over each
    hole of its surface, so its inside is well defined (the caps lie inside the body).

    Returns:
        The part's vertices and its ``(Fp + caps, 3)`` triangles in their indices, wound like
        ``faces``.
    """
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    rim_edges = directed[counts[inverse.ravel()] == 1]  # (B, 2), as wound in their face
    used = np.unique(faces)
    index = np.full(int(faces.max()) + 1, -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    # Holes: connected components of the rim edges (union-find on body vertex indices).
    parent = {int(v): int(v) for v in rim_edges.ravel()}

    def root(v: int) -> int:
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    for a, b in rim_edges:
        parent[root(int(a))] = root(int(b))
    hole_of_edge = np.array([root(int(a)) for a, _ in rim_edges], dtype=np.int64)
    holes = np.unique(hole_of_edge)
    rims = tuple(np.unique(rim_edges[hole_of_edge == h]) for h in holes)
    centre = len(used) + np.searchsorted(holes, hole_of_edge)
    caps = np.stack([index[rim_edges[:, 1]], index[rim_edges[:, 0]], centre], axis=1)
    return _PartVertices(used, rims), np.concatenate([index[faces], caps]).astype(np.int64)


def _points(values: np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3 or len(array) == 0:
        raise ValueError(f"{name} must be an (N, 3) array, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} has non-finite values")
    return array


def _faces(values: np.ndarray, count: int, name: str) -> np.ndarray:
    array = np.asarray(values)
    if array.ndim != 2 or array.shape[1] != 3 or len(array) == 0:
        raise ValueError(f"{name} must be an (F, 3) array, got shape {array.shape}")
    if not np.issubdtype(array.dtype, np.integer) or array.min() < 0 or array.max() >= count:
        raise ValueError(f"{name} must hold vertex indices in [0, {count})")
    return array.astype(np.int64)


@dataclass
class SimResult:
    """A simulated sequence and how far it can be trusted.

    Attributes:
        points: ``(T', N, 3)`` float32 garment vertices of the motion frames kept (m);
            ``T' = T`` when ``ok``, otherwise the frames before the failure.
        checks: one ``FrameCheck`` per frame in ``points``, plus the failing frame's last try.
        substeps: substeps each frame of ``checks`` needed (more than asked after a retry).
        bad: per frame of ``checks``, whether it failed its checks even with the most substeps
            (kept unless strict; the last one of a failed sequence is the failing frame).
        projected: per frame of ``checks``, the share of vertices the end-of-frame projection
            moved out of the body (``ContactSettings.project``; 0 when off).
        released: per frame of ``checks``, whether its kept try dropped the ``ContactRelease``
            contacts (``ContactSettings.release``).
        lead_in_checks: one ``FrameCheck`` per lead-in and settle frame simulated.
        lead_in_bad: per lead-in and settle frame, whether it was bad.
        seconds_per_frame: mean wall time per simulated frame (lead-in included, checks and
            retries included), in seconds.
        status: ``"ok"`` (every motion frame simulated; some may be ``bad``) or ``"failed"``.
        message: why it failed (empty when ``ok``).
    """

    points: np.ndarray
    checks: list[FrameCheck] = field(default_factory=list)
    substeps: list[int] = field(default_factory=list)
    bad: list[bool] = field(default_factory=list)
    projected: list[float] = field(default_factory=list)
    released: list[bool] = field(default_factory=list)
    lead_in_checks: list[FrameCheck] = field(default_factory=list)
    lead_in_bad: list[bool] = field(default_factory=list)
    seconds_per_frame: float = 0.0
    status: str = "ok"
    message: str = ""

    @property
    def ok(self) -> bool:
        """Whether the whole motion was simulated (bad frames may be among them)."""
        return self.status == "ok"

    @property
    def bad_frames(self) -> int:
        """Motion and lead-in frames that failed their checks with the most substeps."""
        return int(sum(self.bad) + sum(self.lead_in_bad))

    @classmethod
    def joined(cls, runs: Sequence[SimResult]) -> SimResult:
        """The results of consecutive runs of one motion, each simulated from its own lead-in,
        as one: their motion frames and checks in order, every run's lead-in checks, the mean
        time per simulated frame over them all, and the last run's status (a failed run is
        the last one simulated)."""
        simulated = [len(r.lead_in_checks) + len(r.checks) for r in runs]
        seconds = sum(r.seconds_per_frame * n for r, n in zip(runs, simulated, strict=True))
        return cls(
            points=np.concatenate([r.points for r in runs]),
            checks=[c for r in runs for c in r.checks],
            substeps=[k for r in runs for k in r.substeps],
            bad=[b for r in runs for b in r.bad],
            projected=[p for r in runs for p in r.projected],
            released=[b for r in runs for b in r.released],
            lead_in_checks=[c for r in runs for c in r.lead_in_checks],
            lead_in_bad=[b for r in runs for b in r.lead_in_bad],
            seconds_per_frame=seconds / max(sum(simulated), 1),
            status=runs[-1].status,
            message=runs[-1].message,
        )


def easing(count: int) -> np.ndarray:
    """``(count,)`` weights rising from near 0 to 1 at the last along a smoothstep, 3s² − 2s³ of
    s = 1/count, 2/count, …, 1 (zero slope at both ends): the lead-in's easing."""
    s = np.arange(1, count + 1) / max(count, 1)
    return s * s * (3.0 - 2.0 * s)


def lead_in_frames(body_rest: np.ndarray, body_first: np.ndarray, count: int) -> np.ndarray:
    """Body frames easing from the rest pose into the first frame of a motion.

    Vertices are blended with a smoothstep weight, so the body starts and ends at rest speed.
    Blending vertices shrinks limbs that rotate far (a T-pose arm lowered by 90°); callers
    with a body model should rather interpolate the pose and skin each frame.

    Args:
        body_rest: ``(Vb, 3)`` body in the pose the garment's rest shape fits (m).
        body_first: ``(Vb, 3)`` first frame of the motion (m).
        count: number of frames to return.

    Returns:
        ``(count, Vb, 3)`` frames; the last one equals ``body_first``.
    """
    weight = easing(count)[:, None, None]
    return (1.0 - weight) * body_rest[None] + weight * body_first[None]


def simulate_sequence(
    rest_vertices: np.ndarray,
    faces: np.ndarray,
    body_faces: np.ndarray,
    body_frames: np.ndarray,
    *,
    body_rest: np.ndarray | None = None,
    lead_in: np.ndarray | int = 10,
    settle_frames: int = 5,
    material: ClothMaterial | None = None,
    substeps: int = SUBSTEPS,
    iterations: int = ITERATIONS,
    fps: float = 30.0,
    contact: ContactSettings | None = None,
    limits: CheckLimits | None = None,
    max_substeps: int = MAX_SUBSTEPS,
    strict: bool = False,
    max_bad_run: int = MAX_BAD_RUN,
    progress: Callable[[int, int], None] | None = None,
    initial_vertices: np.ndarray | None = None,
    body_parts: np.ndarray | None = None,
    release: ContactRelease | None = None,
    first_frame: int = 0,
) -> SimResult:
    """Simulate a garment through a body motion, checking every frame.

    The garment starts in its rest shape (or at ``initial_vertices``) on ``body_rest`` (the
    body it was modelled on). The body then eases into ``body_frames[0]`` over the lead-in,
    holds it for ``settle_frames`` so the cloth settles, and plays the motion. Each frame is
    projected out of the body (``ContactSettings.project``) and checked (``measure_frame``:
    the shared winding-number query against the frame's body, judged on inside-elsewhere, see
    ``CheckLimits``). A frame that fails its checks is simulated again from the state before it
    with twice the substeps, up to ``max_substeps``, then, where ``contact.release`` is
    ``"retry"``, once more with ``max_substeps`` and the ``release`` contacts dropped (that try
    is kept). A frame that still fails is *bad*: with ``strict`` the sequence stops there with
    status "failed"; otherwise it is kept, flagged in ``SimResult.bad``, and the simulation goes
    on from it, unless it has NaNs or a vertex farther than ``limits.max_distance`` from the
    body (the garment fell off), or it is the ``max_bad_run + 1``-th bad frame in a row: those
    fail.

    Args:
        rest_vertices: ``(N, 3)`` garment rest shape (m), worn by ``body_rest``.
        faces: ``(F, 3)`` garment triangles.
        body_faces: ``(Fb, 3)`` body triangles, counter-clockwise seen from outside.
        body_frames: ``(T, Vb, 3)`` posed body vertices per frame (m) at ``fps``.
        body_rest: ``(Vb, 3)`` body the garment fits at rest; ``body_frames[0]`` by default
            (then there is no lead-in).
        lead_in: ``(W, Vb, 3)`` body frames from ``body_rest`` to ``body_frames[0]``, or a
            frame count for ``lead_in_frames``.
        settle_frames: frames holding ``body_frames[0]`` before the motion.
        material: the fabric; SNUG's cotton by default.
        substeps: solver steps per frame (doubled on retries).
        iterations: non-linear iterations per solver step.
        fps: frames per second of ``body_frames``.
        contact: contact parameters; ``ContactSettings()`` by default.
        limits: what makes a frame bad; ``CheckLimits()`` by default.
        max_substeps: most substeps a retried frame may use.
        strict: stop at the first bad frame instead of keeping it.
        max_bad_run: most consecutive bad frames kept (not strict).
        progress: called as ``progress(done, total)`` after each simulated frame.
        initial_vertices: ``(N, 3)`` garment start positions on ``body_rest`` (e.g. the draped
            template); ``rest_vertices`` by default.
        body_parts: ``(Fb,)`` part label per body triangle, one collider each (see
            ``GarmentSimulator``); the frame checks always use the whole body.
        release: the body contacts that ``contact.release`` drops; none when None.
        first_frame: the motion frame that ``body_frames[0]`` is (a run of a longer motion),
            by which a failure names its frame.

    Returns:
        The ``SimResult``; check ``ok`` before using ``points``, and ``bad`` for the frames
        kept although they failed their checks.
    """
    body_frames = np.asarray(body_frames, dtype=np.float64)
    if body_frames.ndim != 3 or body_frames.shape[2] != 3 or len(body_frames) == 0:
        raise ValueError(f"body_frames must be a (T, Vb, 3) array, got {body_frames.shape}")
    start_body = body_frames[0] if body_rest is None else _points(body_rest, "body_rest")
    if start_body.shape != body_frames.shape[1:]:
        raise ValueError(f"body_rest must be {body_frames.shape[1:]}, got {start_body.shape}")
    if max_bad_run < 0:
        raise ValueError(f"max_bad_run must be >= 0, got {max_bad_run}")
    if isinstance(lead_in, (int, np.integer)):
        count = int(lead_in) if body_rest is not None else 0
        lead = lead_in_frames(start_body, body_frames[0], count)
    else:
        lead = np.asarray(lead_in, dtype=np.float64).reshape(-1, *body_frames.shape[1:])
    warmup = np.concatenate([lead, np.repeat(body_frames[:1], settle_frames, axis=0)])
    limits = limits or CheckLimits()
    contact = contact or ContactSettings()

    sim = GarmentSimulator(
        rest_vertices, faces, body_faces, start_body, material,
        substeps=substeps, iterations=iterations, fps=fps, contact=contact,
        initial_vertices=initial_vertices, body_parts=body_parts, release=release,
    )  # fmt: skip
    mode = contact.release if release is not None else "never"  # nothing to release: never
    edges = unique_edges(np.asarray(faces))
    rest = np.asarray(rest_vertices, dtype=np.float64)
    rest_lengths = edge_lengths(rest, edges)

    result = SimResult(points=np.zeros((0, sim.num_vertices, 3), dtype=np.float32))
    frames: list[np.ndarray] = []
    total = len(warmup) + len(body_frames)
    started = time.perf_counter()
    bad_run = 0
    for index, body in enumerate(np.concatenate([warmup, body_frames])):
        snapshot = sim.get_state()
        tries = substeps
        sim.releasing = mode == "always"
        while True:
            sim.substeps = tries
            points = sim.step(body)
            moved, query = 0.0, None
            if contact.project and np.isfinite(points).all():
                # One query serves the push-out's first pass and, when nothing moves, the check.
                query = signed_distance(
                    points[None], body[None], sim.surface, probe_below=PUSH_OUT_EPS
                )
                pushed = push_out(points[None], body[None], sim.surface, first=query)[0]
                changed = np.any(pushed != points, axis=1)
                if changed.any():
                    sim.project(pushed)
                    points = sim.points
                    moved, query = float(changed.mean()), None
            check = measure_frame(points, body, sim.surface, rest_lengths, edges, limits, query)
            reasons = check.failures(limits)
            if not reasons:
                break
            if tries * 2 <= max_substeps:
                tries *= 2
            elif mode == "retry" and not sim.releasing:
                sim.releasing = True
            else:
                break
            sim.set_state(snapshot)
        sim.substeps = substeps
        in_motion = index >= len(warmup)
        bad = bool(reasons)
        bad_run = bad_run + 1 if bad else 0
        if in_motion:
            result.checks.append(check)
            result.substeps.append(tries)
            result.bad.append(bad)
            result.projected.append(moved)
            result.released.append(sim.releasing)
        else:
            result.lead_in_checks.append(check)
            result.lead_in_bad.append(bad)
        stop = ""
        if bad and strict:
            stop = ", ".join(reasons) + check.forced_note()
        elif bad and check.fatal(limits):
            stop = ", ".join(check.fatal(limits))
        elif bad_run > max_bad_run:
            stop = f"{bad_run} bad frames in a row, the last with {', '.join(reasons)}"
            stop += check.forced_note()
        if stop:
            stage = f"lead-in frame {index}"
            if in_motion:
                stage = f"motion frame {first_frame + index - len(warmup)}"
            elif first_frame:
                stage += f" before motion frame {first_frame}"
            if not in_motion:  # the failing frame's check goes with the motion's too
                result.checks.append(check)
                result.substeps.append(tries)
                result.bad.append(True)
                result.projected.append(moved)
                result.released.append(sim.releasing)
            result.status = "failed"
            result.message = f"{stage}: {stop} (with {tries} substeps)"
            break
        if in_motion:
            frames.append(points)
        if progress is not None:
            progress(index + 1, total)
    result.seconds_per_frame = (time.perf_counter() - started) / (index + 1)
    if frames:
        result.points = np.stack(frames).astype(np.float32)
    return result
