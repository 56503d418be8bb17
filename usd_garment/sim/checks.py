"""Per-frame sanity checks of a simulated garment against the posed body: NaNs, vertices inside
the body, vertices far from it (a garment that fell through reads 0 % inside), edge stretch.
The signed distances to the body come from the caller (the simulator queries its collider)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CheckLimits:
    """Thresholds that make a simulated frame bad.

    Attributes:
        inside_depth: a vertex counts as penetrating when its signed distance is below
            ``-inside_depth`` (m); the contact radius of the solver lets cloth graze the skin.
        max_inside_share: largest tolerated share of penetrating vertices (0..1).
        max_distance: largest tolerated distance of any vertex from the body surface (m).
        max_stretch: largest tolerated p99 of current / rest edge length.
    """

    inside_depth: float = 2e-3
    max_inside_share: float = 0.002
    max_distance: float = 0.15
    max_stretch: float = 1.3


@dataclass(frozen=True)
class FrameCheck:
    """What ``check_frame`` measured on one frame.

    Attributes:
        nan_count: garment vertices with a NaN or infinite coordinate.
        inside_share: share of vertices with signed distance < 0 (inside the body).
        penetrating_share: share of vertices deeper than ``CheckLimits.inside_depth``.
        max_distance: largest unsigned distance of a vertex from the body surface (m).
        stretch_p99: 99th percentile of current / rest edge length.
        stretch_max: largest current / rest edge length.
    """

    nan_count: int
    inside_share: float
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
            reasons.append(f"{100 * self.penetrating_share:.2f}% of vertices inside the body")
        if not self.max_distance <= limits.max_distance:
            reasons.append(f"a vertex {self.max_distance:.3f} m from the body")
        if not self.stretch_p99 <= limits.max_stretch:
            reasons.append(f"edge stretch p99 {self.stretch_p99:.3f}")
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


def check_frame(
    points: np.ndarray,
    body_distance: np.ndarray,
    rest_edge_lengths: np.ndarray,
    edges: np.ndarray,
    limits: CheckLimits,
) -> FrameCheck:
    """Measure one simulated frame.

    Args:
        points: ``(N, 3)`` garment vertices (m).
        body_distance: ``(N,)`` signed distance of ``points`` to the posed body of the same
            frame (m, negative inside); ignored where ``points`` are not finite.
        rest_edge_lengths: ``(E,)`` rest lengths of ``edges`` (m).
        edges: ``(E, 2)`` garment edges (see ``unique_edges``).
        limits: thresholds; only ``inside_depth`` is used here.

    Returns:
        The frame's ``FrameCheck``; with NaNs present, the geometric figures are NaN.
    """
    finite = np.isfinite(points).all(axis=1)
    nan_count = int((~finite).sum())
    if nan_count:
        nan = float("nan")
        return FrameCheck(nan_count, nan, nan, nan, nan, nan)
    sdf = np.asarray(body_distance, dtype=np.float64)
    ratio = edge_lengths(points, edges) / np.maximum(rest_edge_lengths, 1e-12)
    return FrameCheck(
        nan_count=0,
        inside_share=float((sdf < 0).mean()),
        penetrating_share=float((sdf < -limits.inside_depth).mean()),
        max_distance=float(np.abs(sdf).max()),
        stretch_p99=float(np.percentile(ratio, 99)),
        stretch_max=float(ratio.max()),
    )
