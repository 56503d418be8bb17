"""Anatomical limits of the 23 SMPL body joints, as boxes of Euler angles in SMPL's local frames,
with checks and clamping of axis-angle poses against them.

Convention: a joint's local rotation ``R`` (the axis-angle ``pose[j]``) is read as extrinsic
Euler angles ``(ex, ey, ez)`` about the parent's axes, which in the rest T-pose are the world
axes (Y up, the body faces +Z, its left is +X): ``R = Rz(ez) · Ry(ey) · Rx(ex)`` (scipy order
``"xyz"``) for every joint but the elbows, ``R = Ry(ey) · Rz(ez) · Rx(ex)`` (order ``"xzy"``) for
the elbows, whose flexion about Y exceeds π/2. The middle angle of every joint's order has its
range inside (−π/2, π/2), so the angles of a rotation are unique. The root (pelvis) orientation
is not limited. Angles are always listed as (x, y, z), whatever the order.

Signs, checked against the body's forward pass in ``tests/test_motion.py``:

- knee: flexing (the shin swings back) is ``+ex``; hip: the thigh swinging forward is ``−ex``,
  the left leg moving out sideways (abduction) is ``+ez``;
- ankle: toes down (plantar flexion) is ``+ex``; the ball of the foot bending up is ``−ex``;
- spine1..3, neck, head: bending forward is ``+ex``, turning towards the body's left is ``+ey``,
  leaning towards the body's right is ``+ez``;
- left shoulder: raising the arm sideways is ``+ez`` (lowering it to the side ``−ez``), moving it
  forward is ``−ey``, twisting it about its own axis is ``ex``; left collar: shrugging is ``+ez``;
- left elbow: flexing (the forearm comes forward from the T-pose) is ``−ey``; left wrist: the
  hand bending palm-down is ``−ez``;
- right side: the mirror image through the YZ plane, ``(ex, ey, ez) → (ex, −ey, −ez)``, so
  raising the right arm is ``−ez`` and flexing the right elbow ``+ey``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from usd_garment.body.joints import NUM_JOINTS, SMPL_JOINT_NAMES

#: scipy Euler order (extrinsic) of each joint's angles.
EULER_ORDERS: tuple[str, ...] = tuple(
    "xzy" if name.endswith("_elbow") else "xyz" for name in SMPL_JOINT_NAMES
)

# (lo, hi) per Euler axis x, y, z in radians, for the centre and the left joints.
_LEFT_AND_CENTRE: dict[str, tuple[tuple[float, float], ...]] = {
    "left_hip": ((-2.0, 0.6), (-0.6, 0.6), (-0.45, 1.0)),
    "spine1": ((-0.3, 0.6), (-0.4, 0.4), (-0.3, 0.3)),
    "left_knee": ((0.0, 2.4), (-0.15, 0.15), (-0.1, 0.1)),
    "spine2": ((-0.3, 0.5), (-0.4, 0.4), (-0.3, 0.3)),
    "left_ankle": ((-0.7, 0.8), (-0.4, 0.4), (-0.4, 0.4)),
    "spine3": ((-0.3, 0.5), (-0.4, 0.4), (-0.3, 0.3)),
    "left_foot": ((-0.7, 0.3), (-0.1, 0.1), (-0.1, 0.1)),
    "neck": ((-0.5, 0.6), (-0.6, 0.6), (-0.4, 0.4)),
    "left_collar": ((-0.2, 0.2), (-0.3, 0.3), (-0.2, 0.5)),
    "head": ((-0.4, 0.5), (-0.6, 0.6), (-0.3, 0.3)),
    "left_shoulder": ((-1.2, 1.2), (-1.45, 0.8), (-1.45, 1.5)),
    "left_elbow": ((-0.8, 0.8), (-2.5, 0.05), (-0.15, 0.15)),
    "left_wrist": ((-0.8, 0.8), (-0.4, 0.4), (-1.2, 1.0)),
    "left_hand": ((-0.2, 0.2), (-0.2, 0.2), (-0.8, 0.2)),
}


def _limit_table() -> np.ndarray:
    """``(24, 3, 2)`` radians: (lo, hi) of each Euler angle of each joint; the root is ±∞."""
    table = np.empty((NUM_JOINTS, 3, 2))
    table[..., 0], table[..., 1] = -np.inf, np.inf
    for j, name in enumerate(SMPL_JOINT_NAMES):
        if name in _LEFT_AND_CENTRE:
            table[j] = _LEFT_AND_CENTRE[name]
        elif name.startswith("right_"):
            (x, (ylo, yhi), (zlo, zhi)) = _LEFT_AND_CENTRE["left_" + name[len("right_") :]]
            table[j] = (x, (-yhi, -ylo), (-zhi, -zlo))
    return table


#: ``(24, 3, 2)`` radians: ``JOINT_LIMITS[j, axis] = (lo, hi)`` of Euler angle ``axis`` (x, y, z)
#: of joint ``j``; the root row is ``(−∞, ∞)``.
JOINT_LIMITS: np.ndarray = _limit_table()
JOINT_LIMITS.setflags(write=False)


def _axes(order: str) -> list[int]:
    """Positions of x, y, z in the angle list of a scipy Euler ``order``."""
    return [order.index(axis) for axis in "xyz"]


def pose_to_euler(pose: np.ndarray) -> np.ndarray:
    """Axis-angle ``(..., 24, 3)`` (rad) to Euler angles ``(..., 24, 3)`` (rad, listed as
    x, y, z, in each joint's :data:`EULER_ORDERS`)."""
    pose = np.asarray(pose, dtype=np.float64)
    euler = np.empty_like(pose)
    for j, order in enumerate(EULER_ORDERS):
        angles = Rotation.from_rotvec(pose[..., j, :].reshape(-1, 3)).as_euler(order)
        euler[..., j, :] = angles[:, _axes(order)].reshape(pose[..., j, :].shape)
    return euler


def euler_to_pose(euler: np.ndarray) -> np.ndarray:
    """Euler angles ``(..., 24, 3)`` (rad, x, y, z, in each joint's :data:`EULER_ORDERS`) to
    axis-angle ``(..., 24, 3)`` (rad)."""
    euler = np.asarray(euler, dtype=np.float64)
    pose = np.empty_like(euler)
    for j, order in enumerate(EULER_ORDERS):
        angles = euler[..., j, :].reshape(-1, 3)[:, ["xyz".index(a) for a in order]]
        pose[..., j, :] = (
            Rotation.from_euler(order, angles).as_rotvec().reshape(pose[..., j, :].shape)
        )
    return pose


def clamp_to_limits(pose: np.ndarray) -> np.ndarray:
    """``pose`` ``(..., 24, 3)`` axis-angle (rad) with every joint's Euler angles clipped into
    :data:`JOINT_LIMITS` (float64, same shape); the root is returned unchanged."""
    pose = np.asarray(pose, dtype=np.float64)
    euler = np.clip(pose_to_euler(pose), JOINT_LIMITS[..., 0], JOINT_LIMITS[..., 1])
    clamped = euler_to_pose(euler)
    clamped[..., 0, :] = pose[..., 0, :]
    return clamped


def limit_violation(pose: np.ndarray) -> np.ndarray:
    """How far each Euler angle of ``pose`` ``(..., 24, 3)`` lies outside its limits (rad, ≥ 0,
    same shape; 0 inside)."""
    euler = pose_to_euler(pose)
    below = JOINT_LIMITS[..., 0] - euler
    above = euler - JOINT_LIMITS[..., 1]
    return np.maximum(np.maximum(below, above), 0.0)


def within_limits(pose: np.ndarray, tol: float = 1e-4) -> bool:
    """Whether every joint of ``pose`` ``(..., 24, 3)`` axis-angle (rad) lies within its limits,
    up to ``tol`` radians."""
    return bool(np.all(limit_violation(pose) <= tol))
