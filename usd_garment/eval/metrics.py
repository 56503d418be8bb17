"""Garment quality figures per frame and over a sequence: collisions with the posed body (share of
vertices inside by winding number, split into forced and elsewhere, and within 1 mm of the
surface; penetration depth; where on the body the vertices inside elsewhere are), distance to a
reference, jitter and NaNs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from usd_garment.body.joints import SMPL_JOINT_NAMES
from usd_garment.eval.body_distance import BodyPool, BodySurface, signed_distance

#: A vertex is "within" the body's contact band when its signed distance is below this (m).
CONTACT_BAND = 1e-3


@dataclass
class GarmentMetrics:
    """Per-frame figures ``(T,)`` of a posed garment sequence.

    Attributes:
        inside_share: share of (finite) garment vertices inside the body (winding number > 0.5).
        inside_forced_share: share inside where the closest body point lies itself inside the
            body (a limb pressed into the trunk: forced on any garment by the animation).
        inside_elsewhere_share: share inside elsewhere (the garment method's fault).
        within_1mm_share: share with signed distance to the body surface < 1 mm (inside
            included).
        mean_penetration_mm: mean depth of the vertices inside the body (mm); 0 when none.
        max_penetration_mm: largest depth inside the body (mm); 0 when none.
        max_elsewhere_mm: largest depth of the vertices inside elsewhere (mm); 0 when none.
        reference_mm: mean per-vertex distance to a reference sequence (mm); NaN without one.
        reference_shift_mm: length of the frame's mean offset from the reference (mm): the part
            of the error that moves the whole garment (a garment riding up, or left behind);
            NaN without a reference.
        reference_unshifted_mm: mean per-vertex distance to the reference with that offset
            taken away (mm): the error in the garment's shape and folds; NaN without one.
        acceleration: mean per-vertex acceleration magnitude (m/s²), central second difference;
            NaN on the first and last frame, and on the two frames whose difference spans a cut
            of the motion (a teleport of the body is not the garment's acceleration).
        nan_count: vertices with a NaN or infinite coordinate.
        elsewhere_part_counts: ``(J,)`` vertex-frames inside elsewhere over the sequence, by the
            body part of their closest point (the joint that moves its triangle most); None when
            the body's parts were not given.
    """

    inside_share: np.ndarray
    inside_forced_share: np.ndarray
    inside_elsewhere_share: np.ndarray
    within_1mm_share: np.ndarray
    mean_penetration_mm: np.ndarray
    max_penetration_mm: np.ndarray
    max_elsewhere_mm: np.ndarray
    reference_mm: np.ndarray
    reference_shift_mm: np.ndarray
    reference_unshifted_mm: np.ndarray
    acceleration: np.ndarray
    nan_count: np.ndarray
    elsewhere_part_counts: np.ndarray | None = None

    def elsewhere_by_part(self) -> dict[str, float]:
        """Share of the vertex-frames inside elsewhere on each body part that has any, largest
        first, keyed by SMPL joint name (empty when none is inside elsewhere or the parts are
        unknown)."""
        counts = self.elsewhere_part_counts
        if counts is None or not counts.any():
            return {}
        total = int(counts.sum())
        order = np.argsort(-counts, kind="stable")
        return {SMPL_JOINT_NAMES[j]: float(counts[j] / total) for j in order if counts[j]}

    def summary(self) -> dict[str, float | int | None]:
        """Sequence figures: means over frames (max for depth, sum for NaNs); None if undefined."""
        out: dict[str, float | int | None] = {}
        for name, values in self.per_frame().items():
            arr = np.asarray(values, dtype=np.float64)
            finite = arr[np.isfinite(arr)]
            if name == "nan_count":
                out[name] = int(arr.sum())
            elif finite.size == 0:
                out[name] = None
            elif name.startswith("max_"):
                out[name] = float(finite.max())
            else:
                out[name] = float(finite.mean())
        return out

    def per_frame(self) -> dict[str, np.ndarray]:
        return {
            "inside_share": self.inside_share,
            "inside_forced_share": self.inside_forced_share,
            "inside_elsewhere_share": self.inside_elsewhere_share,
            "within_1mm_share": self.within_1mm_share,
            "mean_penetration_mm": self.mean_penetration_mm,
            "max_penetration_mm": self.max_penetration_mm,
            "max_elsewhere_mm": self.max_elsewhere_mm,
            "reference_mm": self.reference_mm,
            "reference_shift_mm": self.reference_shift_mm,
            "reference_unshifted_mm": self.reference_unshifted_mm,
            "acceleration": self.acceleration,
            "nan_count": self.nan_count,
        }

    def to_json(self) -> dict[str, Any]:
        """Summary and per-frame lists, NaN written as None (valid JSON)."""

        def clean(values: np.ndarray) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in np.asarray(values, float)]

        return {
            "summary": self.summary(),
            "elsewhere_by_part": self.elsewhere_by_part(),
            "per_frame": {k: clean(v) for k, v in self.per_frame().items()},
        }


def evaluate_garment(
    points: np.ndarray,
    body_vertices: np.ndarray,
    body_faces: np.ndarray,
    fps: float,
    reference: np.ndarray | None = None,
    pool: BodyPool | None = None,
    face_parts: np.ndarray | None = None,
    cuts: Sequence[int] = (),
    steady: np.ndarray | None = None,
) -> GarmentMetrics:
    """Figures of a garment ``(T, N, 3)`` (m) on the posed body ``(T, V, 3)`` with faces
    ``(F, 3)``, sampled at ``fps``; ``reference`` ``(T, N, 3)`` (m) is optional; ``pool``:
    worker processes that measure blocks of frames (the same figures); ``face_parts`` ``(F,)``:
    the SMPL joint of each body face (:func:`face_joints`), to count where the vertices inside
    elsewhere are; ``cuts``: the frames where the motion starts anew
    (:func:`~usd_garment.motion.cuts.motion_cuts`), around which no acceleration is measured;
    ``steady`` ``(T, N, 3)`` (m): the garment with the body's jumps of the root alone taken out
    (:func:`~usd_garment.motion.jumps.jump_maps`), whose acceleration is measured in their
    place (None: the garment's own)."""
    points = np.asarray(points, dtype=np.float64)
    t_frames, n = points.shape[:2]
    finite = np.isfinite(points).all(axis=-1)  # (T, N)
    safe = np.where(finite[..., None], points, 0.0)
    surface = BodySurface(body_faces, body_vertices.shape[1])
    query = signed_distance(safe, body_vertices, surface, pool=pool)
    dist = np.where(finite, query.distance, np.nan)
    count = np.maximum(finite.sum(axis=1), 1)
    inside = dist < 0
    forced = query.forced & finite
    elsewhere = query.elsewhere & finite
    part_counts = None
    if face_parts is not None:
        where = np.asarray(face_parts)[query.face[elsewhere]]
        part_counts = np.bincount(where, minlength=len(SMPL_JOINT_NAMES))
    depth = np.where(inside, -dist, 0.0)
    n_inside = inside.sum(axis=1)
    reference_mm, shift_mm, unshifted_mm = _reference_errors(points, reference)
    acceleration = np.full(t_frames, np.nan)
    if t_frames >= 3:
        moving = safe if steady is None else np.where(finite[..., None], steady, 0.0)
        acc = (moving[2:] - 2.0 * moving[1:-1] + moving[:-2]) * fps**2
        ok = finite[2:] & finite[1:-1] & finite[:-2]
        norm = np.where(ok, np.linalg.norm(acc, axis=-1), np.nan)
        acceleration[1:-1] = np.nanmean(np.where(ok.any(axis=1)[:, None], norm, 0.0), axis=1)
        for k in cuts:  # the central differences at k - 1 and at k span the cut
            acceleration[max(k - 1, 0) : k + 1] = np.nan
    return GarmentMetrics(
        inside_share=n_inside / count,
        inside_forced_share=forced.sum(axis=1) / count,
        inside_elsewhere_share=elsewhere.sum(axis=1) / count,
        within_1mm_share=(dist < CONTACT_BAND).sum(axis=1) / count,
        mean_penetration_mm=1e3 * depth.sum(axis=1) / np.maximum(n_inside, 1),
        max_penetration_mm=1e3 * depth.max(axis=1, initial=0.0),
        max_elsewhere_mm=1e3 * np.where(elsewhere, depth, 0.0).max(axis=1, initial=0.0),
        reference_mm=reference_mm,
        reference_shift_mm=shift_mm,
        reference_unshifted_mm=unshifted_mm,
        acceleration=acceleration,
        nan_count=n - finite.sum(axis=1),
        elsewhere_part_counts=part_counts,
    )


def _reference_errors(
    points: np.ndarray, reference: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame ``(T,)`` errors (mm) of a garment ``(T, N, 3)`` (m) against ``reference`` of the
    same shape: the mean per-vertex distance, the length of the mean offset, and the mean
    distance once that offset is taken away; all NaN without a reference (NaN vertices are
    left out)."""
    nan = np.full(points.shape[0], np.nan)
    if reference is None:
        return nan, nan.copy(), nan.copy()
    ref = np.asarray(reference, dtype=np.float64)
    if ref.shape != points.shape:
        raise ValueError(f"reference must be {points.shape}, got {ref.shape}")
    offset = points - ref  # (T, N, 3)
    shift = np.nanmean(offset, axis=1, keepdims=True)  # (T, 1, 3)
    return (
        1e3 * np.nanmean(np.linalg.norm(offset, axis=-1), axis=1),
        1e3 * np.linalg.norm(shift[:, 0], axis=-1),
        1e3 * np.nanmean(np.linalg.norm(offset - shift, axis=-1), axis=1),
    )


def face_joints(weights: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The body part of each face ``(F,)``: the joint with the largest skinning weight summed
    over its three corners; ``weights`` ``(V, J)``, ``faces`` ``(F, 3)``."""
    return np.asarray(weights)[np.asarray(faces)].sum(axis=1).argmax(axis=1)
