"""Per-frame sanity checks of a simulated garment against the posed body: NaNs, vertices inside
the body, vertices far from it (a garment that fell through reads 0 % inside), edge stretch.

Inside is the project's one inside test, the generalized winding number of
``usd_garment.eval.body_distance.signed_distance``. An inside vertex is *forced* where its
closest body point lies itself inside the body (a limb pressed into the trunk: no garment can be
outside there) and *elsewhere* otherwise; frames are judged on the elsewhere share only.
Shapes: N garment vertices, E garment edges, V body vertices. Units: metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usd_garment.eval.body_distance import BodyDistance, BodySurface, signed_distance


@dataclass(frozen=True)
class CheckLimits:
    """Thresholds that make a simulated frame bad.

    Attributes:
        inside_depth: an inside-elsewhere vertex counts as penetrating when its signed distance
            is below ``-inside_depth`` (m); the contact radius of the solver lets cloth graze
            the skin.
        max_inside_share: largest tolerated share of penetrating vertices (0..1): the per-frame
            acceptance target for inside-elsewhere (0.5 %), so that a frame meeting the target
            is never retried or flagged (cloth pinched where an arm lies against the trunk,
            closer than two contact radii but not intersecting it, reads 0.1-0.4 % here).
        max_distance: largest tolerated distance of any vertex from the body surface (m): a
            vertex farther than this means the garment fell off (fatal even when bad frames
            are kept). Per garment by :meth:`for_garment`: a skirt's hem swings free of the
            legs.
        far_distance: largest distance of any vertex from the body surface (m) of a good frame,
            the ground truth's target (at most ``max_distance``): a frame beyond it is
            simulated again with more substeps, as cloth swung out by a fast turn is
            under-resolved with few (a T-shirt's hem in a 475°/s spin: 11.7 cm from the body
            with 4 substeps a frame, 10.4 cm with 16), and kept flagged bad if it stays
            beyond.
        max_stretch: largest tolerated p99 of current / rest edge length.
        max_edge_stretch: largest tolerated current / rest length of any single edge: a dress
            hem snagged on a thigh or a hand in a run stretches a few edges 3–7× while the p99
            stays under ``max_stretch``; more substeps avoid the snag (v7s's run m03: largest
            edge 6.8× with 4 substeps and retries, 1.7× with 16 throughout), so a frame beyond
            it is simulated again with more, from where the snag begins.
    """

    inside_depth: float = 2e-3
    max_inside_share: float = 0.005
    max_distance: float = 0.15
    far_distance: float = 0.10
    max_stretch: float = 1.3
    max_edge_stretch: float = 2.5

    @classmethod
    def for_garment(cls, garment: str) -> CheckLimits:
        """The default limits for ``garment`` (a name of ``GARMENT_NAMES``): the T-shirt's
        fell-off distance is 15 cm and its target 10 cm; a dress's hem hangs up to ~30 cm from
        the thighs in a squat or a stride, so both are :data:`SKIRT_MAX_DISTANCE`."""
        if garment == "dress":
            return cls(max_distance=SKIRT_MAX_DISTANCE, far_distance=SKIRT_MAX_DISTANCE)
        return cls()


#: Fell-off distance of garments with a skirt (m): beyond the hem's free swing.
SKIRT_MAX_DISTANCE = 0.4


@dataclass(frozen=True)
class FrameCheck:
    """What ``check_frame`` measured on one frame.

    Attributes:
        nan_count: garment vertices with a NaN or infinite coordinate.
        inside_share: share of vertices inside the body (winding number > 0.5), forced or not.
        inside_forced_share: share of vertices inside where the pose forces it (their closest
            body point lies inside another body part).
        inside_elsewhere_share: share of vertices inside, not forced (the simulation's fault).
        penetrating_share: share of inside-elsewhere vertices deeper than
            ``CheckLimits.inside_depth``: what the frame is judged on.
        max_distance: largest unsigned distance of a vertex from the body surface (m).
        stretch_p99: 99th percentile of current / rest edge length.
        stretch_max: largest current / rest edge length.
    """

    nan_count: int
    inside_share: float
    inside_forced_share: float
    inside_elsewhere_share: float
    penetrating_share: float
    max_distance: float
    stretch_p99: float
    stretch_max: float

    def failures(self, limits: CheckLimits) -> list[str]:
        """Human-readable reasons this frame breaks ``limits`` (empty when it is good)."""
        reasons = []
        if self.nan_count:
            reasons.append(f"{self.nan_count} NaN vertices")
        if self.penetrating_share > limits.max_inside_share:
            reasons.append(
                f"{100 * self.penetrating_share:.2f}% of vertices inside the body "
                f"(not forced by the pose)"
            )
        if not self.max_distance <= limits.far_distance:
            reasons.append(f"a vertex {self.max_distance:.3f} m from the body")
        if not self.stretch_p99 <= limits.max_stretch:
            reasons.append(f"edge stretch p99 {self.stretch_p99:.3f}")
        if not self.stretch_max <= limits.max_edge_stretch:
            reasons.append(f"an edge stretched {self.stretch_max:.2f}x")
        return reasons

    def forced_note(self) -> str:
        """A clause for a failure message naming the share of vertices inside the body where the
        pose forces it ("" where none is): cloth held where a limb passes into the trunk (a
        capture retargeted with its arms through the body) fails on stretch with it, cloth
        stretched in open air without it."""
        if not self.inside_forced_share > 0:
            return ""
        return (
            f"; {100 * self.inside_forced_share:.2f}% of the vertices inside the body where the "
            "pose presses a limb into it"
        )

    def fatal(self, limits: CheckLimits) -> list[str]:
        """The reasons no later frame can recover from: NaN, or a vertex farther than
        ``limits.max_distance`` from the body (the garment fell off)."""
        reasons = []
        if self.nan_count:
            reasons.append(f"{self.nan_count} NaN vertices")
        if not self.max_distance <= limits.max_distance:
            reasons.append(f"a vertex {self.max_distance:.3f} m from the body (fell off)")
        return reasons


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """Undirected edges of a triangle mesh.

    Args:
        faces: ``(F, 3)`` vertex indices.

    Returns:
        ``(E, 2)`` int64 vertex index pairs, each edge once, smaller index first.
    """
    pairs = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    return np.unique(np.sort(pairs, axis=1), axis=0)


def edge_lengths(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Lengths ``(..., E)`` (m) of ``edges`` ``(E, 2)`` over points ``(..., N, 3)`` (m)."""
    return np.linalg.norm(points[..., edges[:, 0], :] - points[..., edges[:, 1], :], axis=-1)


def frame_body_distance(
    points: np.ndarray, body_vertices: np.ndarray, surface: BodySurface
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance of one frame's garment to its body with the shared query.

    Args:
        points: ``(N, 3)`` garment vertices (m), all finite.
        body_vertices: ``(V, 3)`` posed body of the same frame (m).
        surface: the body's ``BodySurface``.

    Returns:
        ``(N,)`` float64 signed distance (m, negative inside, winding number) and ``(N,)`` bool
        forced (inside where a body part is pressed into another).
    """
    query = signed_distance(
        np.asarray(points, dtype=np.float32)[None],
        np.asarray(body_vertices, dtype=np.float32)[None],
        surface,
    )
    return query.distance[0], query.forced[0]


def check_frame(
    points: np.ndarray,
    body_distance: np.ndarray,
    rest_edge_lengths: np.ndarray,
    edges: np.ndarray,
    limits: CheckLimits,
    forced: np.ndarray | None = None,
) -> FrameCheck:
    """Measure one simulated frame.

    Args:
        points: ``(N, 3)`` garment vertices (m).
        body_distance: ``(N,)`` signed distance of ``points`` to the posed body of the same
            frame (m, negative inside); ignored where ``points`` are not finite.
        rest_edge_lengths: ``(E,)`` rest lengths of ``edges`` (m).
        edges: ``(E, 2)`` garment edges (see ``unique_edges``).
        limits: thresholds; only ``inside_depth`` is used here.
        forced: ``(N,)`` bool, inside vertices whose penetration the pose forces (see
            ``frame_body_distance``); none by default.

    Returns:
        The frame's ``FrameCheck``; with NaNs present, the geometric figures are NaN.
    """
    finite = np.isfinite(points).all(axis=1)
    nan_count = int((~finite).sum())
    if nan_count:
        nan = float("nan")
        return FrameCheck(nan_count, nan, nan, nan, nan, nan, nan, nan)
    sdf = np.asarray(body_distance, dtype=np.float64)
    inside = sdf < 0
    is_forced = inside & (np.zeros_like(inside) if forced is None else np.asarray(forced, bool))
    elsewhere = inside & ~is_forced
    ratio = edge_lengths(points, edges) / np.maximum(rest_edge_lengths, 1e-12)
    return FrameCheck(
        nan_count=0,
        inside_share=float(inside.mean()),
        inside_forced_share=float(is_forced.mean()),
        inside_elsewhere_share=float(elsewhere.mean()),
        penetrating_share=float((elsewhere & (sdf < -limits.inside_depth)).mean()),
        max_distance=float(np.abs(sdf).max()),
        stretch_p99=float(np.percentile(ratio, 99)),
        stretch_max=float(ratio.max()),
    )


def measure_frame(
    points: np.ndarray,
    body_vertices: np.ndarray,
    surface: BodySurface,
    rest_edge_lengths: np.ndarray,
    edges: np.ndarray,
    limits: CheckLimits,
    query: BodyDistance | None = None,
) -> FrameCheck:
    """``check_frame`` with the shared winding-number query of ``points`` ``(N, 3)`` (m) against
    the frame's body ``(V, 3)`` (m); frames with NaNs are not queried. ``query``: that query
    already made (one frame, any ``probe_below`` ≥ 0), reused instead of a new one."""
    if not np.isfinite(points).all():
        return check_frame(points, np.zeros(len(points)), rest_edge_lengths, edges, limits)
    if query is not None:
        distance, forced = query.distance[0], query.forced[0]
    else:
        distance, forced = frame_body_distance(points, body_vertices, surface)
    return check_frame(points, distance, rest_edge_lengths, edges, limits, forced)
