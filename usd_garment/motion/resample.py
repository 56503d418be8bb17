"""Resample an SMPL motion to another frame rate: slerp joint rotations, lerp translations."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from usd_garment.motion.sequence import SmplMotion


def resample_motion(motion: SmplMotion, fps: float, cuts: Sequence[int] = ()) -> SmplMotion:
    """``motion`` sampled at ``fps`` over the same duration (first frame kept, last frame at or
    before the original end). Time codes restart at 0, one per frame. A frame that falls between
    a cut (a frame of ``cuts``, where the motion starts anew: ``motion_cuts``) and the frame
    before it is that frame before, not a blend of the two sides; the cuts of the result are
    :func:`resampled_cuts`."""
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    t = motion.num_frames
    if np.isclose(fps, motion.fps):
        return motion
    if t == 1:
        return SmplMotion(motion.betas, motion.pose, motion.trans, float(fps),
                          gender=motion.gender, model=motion.model)  # fmt: skip
    duration = (t - 1) / motion.fps
    count = int(np.floor(duration * fps + 1e-6)) + 1
    u = np.arange(count) / fps * motion.fps  # fractional source frame of each output frame
    i0 = np.minimum(np.floor(u).astype(int), t - 2)
    alpha = np.where(np.isin(i0 + 1, cuts), 0.0, u - i0)[:, None]
    trans = (1.0 - alpha) * motion.trans[i0] + alpha * motion.trans[i0 + 1]
    j = motion.pose.shape[1]
    r0 = Rotation.from_rotvec(motion.pose[i0].reshape(-1, 3).astype(np.float64))
    r1 = Rotation.from_rotvec(motion.pose[i0 + 1].reshape(-1, 3).astype(np.float64))
    delta = (r0.inv() * r1).as_rotvec() * np.repeat(alpha, j, axis=0)
    pose = (r0 * Rotation.from_rotvec(delta)).as_rotvec().reshape(count, j, 3)
    return SmplMotion(
        betas=motion.betas,
        pose=pose.astype(motion.pose.dtype),
        trans=trans.astype(motion.trans.dtype),
        fps=float(fps),
        gender=motion.gender,
        model=motion.model,
    )


def resampled_cuts(cuts: Sequence[int], fps: float, to_fps: float, frames: int) -> tuple[int, ...]:
    """The frames of the ``frames`` at ``to_fps`` where the cuts ``cuts`` of a motion at ``fps``
    fall after :func:`resample_motion`: the first at or after each cut's time, each once (two
    cuts between the same two frames are one), none past the last frame."""
    if np.isclose(fps, to_fps):
        return tuple(cuts)
    found = {cut_at(k, fps, to_fps) for k in cuts}
    return tuple(sorted(k for k in found if 0 < k < frames))


def cut_at(cut: int, fps: float, to_fps: float) -> int:
    """The frame at ``to_fps`` where the cut at frame ``cut`` of a motion at ``fps`` falls: the
    first at or after the cut's time (it may lie past the last frame)."""
    return int(np.ceil(cut * to_fps / fps - 1e-6))
