"""Cuts in a motion: frames where the root jumps (a teleport, a heading snapped, two clips joined
end to end), and those the animation declares (``SmplMotion.cut_times``: a splice that changes
only the joints, which no threshold tells from a fast swing), so that what is smoothed over
frames is not smoothed across them.

Units: metres, radians, frames per second.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Literal

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from usd_garment.motion.sequence import SmplMotion

#: A root step that differs from both steps beside it by more than this (m) or
#: :data:`CUT_ROTATION` (rad) starts a cut (where nothing physical accelerates the root faster
#: than :data:`CUT_ACCELERATION` at the motion's frame rate). Real captures stay under 0.021 m
#: and 0.25 rad at 30 frames/s (docs/judge.md, stop 78); the stress suite's root jumps are
#: 0.5 m and π/2.
CUT_DISTANCE = 0.1
CUT_ROTATION = 0.5
#: Root accelerations (m/s², and rad/s² for the turn) that a motion may have without a cut: at a
#: low frame rate a real step may change more than :data:`CUT_DISTANCE` from one to the next.
CUT_ACCELERATION = 50.0
CUT_ANGULAR_ACCELERATION = 400.0


def motion_cuts(motion: SmplMotion) -> tuple[int, ...]:
    """The frames ``k`` (0 < k < T, increasing) where ``motion`` starts anew: its
    :func:`root_cuts` and its declared ``cut_times``, each at the first frame whose time code is
    at or after it (declared times at or before the first frame, or after the last, cut
    nothing)."""
    declared = np.searchsorted(motion.time_codes, np.asarray(motion.cut_times, dtype=np.float64))
    found = set(root_cuts(motion)) | {int(k) for k in declared if 0 < k < motion.num_frames}
    return tuple(sorted(found))


def root_cuts(motion: SmplMotion) -> tuple[int, ...]:
    """The frames ``k`` (1 ≤ k < T) where ``motion`` starts anew: the root's step from frame
    k − 1 to k (its translation, m, or its turn, rad, in the world frame) differs from each
    step beside it (one at the motion's ends; none: no cut) by more than the thresholds."""
    if motion.num_frames < 3:
        return ()
    dt2 = 1.0 / motion.fps**2
    move = np.diff(motion.trans, axis=0)  # (T-1, 3)
    orientation = Rotation.from_rotvec(motion.pose[:, 0])
    turn = (orientation[1:] * orientation[:-1].inv()).as_rotvec()  # (T-1, 3)
    cut = _outliers(move, max(CUT_DISTANCE, CUT_ACCELERATION * dt2))
    cut |= _outliers(turn, max(CUT_ROTATION, CUT_ANGULAR_ACCELERATION * dt2))
    return tuple(int(k) + 1 for k in np.flatnonzero(cut))


def _outliers(steps: np.ndarray, limit: float) -> np.ndarray:
    """``(S,)`` bool: the steps ``(S, 3)`` (S ≥ 2) that differ from each neighbour by more
    than ``limit``."""
    change = np.linalg.norm(np.diff(steps, axis=0), axis=-1) > limit  # (S-1,): k against k+1
    before = np.concatenate([change[:1], change])  # step k against step k-1 (k = 0: its next)
    after = np.concatenate([change, change[-1:]])  # step k against step k+1 (the last: before)
    return before & after


def smooth_runs(
    values: np.ndarray,
    sigma: float,
    cuts: Sequence[int] = (),
    mode: Literal["nearest", "mirror"] = "nearest",
    truncate: float = 4.0,
) -> np.ndarray:
    """A Gaussian of ``sigma`` frames over the first axis of ``values`` ``(T, ...)``, each run
    between ``cuts`` (frames 0 < k < T, increasing) on its own: ``mode`` extends a run beyond
    its ends (scipy's ``gaussian_filter1d``), never into the run across a cut."""
    ends = (0, *cuts, len(values))
    return np.concatenate([
        gaussian_filter1d(values[a:b], sigma, axis=0, mode=mode, truncate=truncate)
        for a, b in itertools.pairwise(ends)
    ])  # fmt: skip
