"""Seeded procedural SMPL motions (walk, run, squat, arm and torso exercises, random smooth
motion) for making training data without motion capture.

Each kind draws its amplitudes, frequencies and phases from ``numpy.random.default_rng(seed)``
and builds per-joint Euler angles (the convention of :mod:`usd_garment.motion.joint_limits`),
which are then clamped to the joint limits. Every motion starts at the rest T-pose with zero
translation and blends into the movement over :data:`BLEND_SECONDS` with a C²-smooth ramp, as
the cloth simulator starts from the garment on the rest body. The root translation follows the
body: the lowest point of the feet stays on the floor (the rest sole height; within about a
centimetre, as that height is smoothed over :data:`LIFT_SMOOTHING`) except during jumps; walk
and run move forward along the heading (+Z, turning slowly) at the average speed at which the
stance foot moves backwards; in place, the feet stay where they are on average. The arms may
hang against the trunk, as they do in motion capture; optionally (``open_shoulders``) they keep
:data:`ARM_CLEARANCE` from the torso whatever the body shape: where the skinned body's arm comes
closer, the shoulders open sideways (smoothly over time) until it does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from usd_garment.body.io import load_body_model
from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS, SMPL_JOINT_NAMES
from usd_garment.body.lbs import batch_rigid_transform, batch_rodrigues, skin
from usd_garment.body.model import BodyModel
from usd_garment.motion.joint_limits import JOINT_LIMITS, clamp_to_limits, euler_to_pose
from usd_garment.motion.sequence import SmplMotion

#: Duration (s) of the blend from the rest T-pose into the motion.
BLEND_SECONDS = 0.5

#: Standard deviation (s) of the Gaussian that smooths the floor-contact height, whose kinks
#: (the lowest sole point switching feet) would otherwise jolt the root.
LIFT_SMOOTHING = 0.03

#: Rest vertices within this height (m) above the lowest one are the sole points (the bottom
#: of the feet, heels included) that touch the floor.
SOLE_BAND = 0.05

#: Smallest distance (m) kept between an arm and the torso surface of the skinned body.
ARM_CLEARANCE = 0.02

#: Arm vertices closer than this (m) to the torso in the rest pose (the armpit, the top of the
#: shoulder) are not held to :data:`ARM_CLEARANCE`: they join the torso.
ARM_ROOT = 0.10

#: Sideways shoulder opening (rad) added per clearance step, and the most steps.
ARM_STEP = 0.05
ARM_STEPS = 16

#: Time scale (s) over which the shoulder opening is spread and smoothed.
ARM_SMOOTHING = 0.2

_TORSO_JOINTS = ("pelvis", "spine1", "spine2", "spine3")
_ARM_JOINTS = ("shoulder", "elbow", "wrist", "hand")
_J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}
_TWO_PI = 2.0 * np.pi


@dataclass
class _Plan:
    """What a motion kind asks for, before the blend-in and the root translation.

    Attributes:
        euler: ``(T, 24, 3)`` Euler angles (rad) of every joint; the root's are relative to
            the heading.
        yaw_rate: turning rate of the heading about +Y (rad/s).
        hop: ``(T,)`` height (m) of the soles above the floor (jumps), zero on the ground.
        stance: ``(T,)`` for walk and run (the body travels along its heading), the foot on the
            ground: 0 left, 1 right, −1 none; None in place.
    """

    euler: np.ndarray
    yaw_rate: float = 0.0
    hop: np.ndarray | None = None
    stance: np.ndarray | None = None


def _set(euler: np.ndarray, name: str, x: object = 0.0, y: object = 0.0, z: object = 0.0) -> None:
    """Set the Euler angles of joint ``name`` (scalars or ``(T,)`` arrays, rad)."""
    frames = euler.shape[0]
    euler[:, _J[name]] = np.stack([np.broadcast_to(v, (frames,)) for v in (x, y, z)], axis=-1)


def _set_side(
    euler: np.ndarray, side: str, part: str, x: object = 0.0, y: object = 0.0, z: object = 0.0
) -> None:
    """Set ``{side}_{part}`` from angles given in the left joint's convention; the right side
    gets the mirror image ``(x, −y, −z)``."""
    sign = 1.0 if side == "left" else -1.0
    _set(euler, f"{side}_{part}", x, sign * np.asarray(y), sign * np.asarray(z))


def _bump(phase: np.ndarray, power: float = 3.0) -> np.ndarray:
    """Smooth periodic bump in [0, 1]: 1 at ``phase`` = 0 (mod 2π), near 0 half a period away."""
    return (0.5 + 0.5 * np.cos(phase)) ** power


def _hanging_arms(euler: np.ndarray, hang: float, elbow: object = 0.2) -> None:
    """Both arms down at the sides (``hang`` rad below horizontal), elbows a little bent."""
    for side in ("left", "right"):
        _set_side(euler, side, "shoulder", z=-hang)
        _set_side(euler, side, "elbow", y=-np.asarray(elbow))


def _gait(t: np.ndarray, rng: np.random.Generator, running: bool) -> _Plan:
    """Walk or run: legs in antiphase, stance feet flat, arms swinging against the legs."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    if running:
        cadence, hip_amp, hip_mid = rng.uniform(1.3, 1.5), rng.uniform(0.45, 0.6), 0.2
        knee_amp, knee_min, knee_peak = rng.uniform(1.5, 1.9), 0.3, 0.1
        swing, elbow, lean = rng.uniform(0.35, 0.55), rng.uniform(1.3, 1.6), rng.uniform(0.1, 0.2)
    else:
        cadence, hip_amp, hip_mid = rng.uniform(0.8, 1.0), rng.uniform(0.3, 0.42), 0.08
        knee_amp, knee_min, knee_peak = rng.uniform(0.9, 1.1), 0.06, 0.4
        swing, elbow, lean = rng.uniform(0.2, 0.4), rng.uniform(0.2, 0.4), rng.uniform(0.0, 0.06)
    hang = rng.uniform(1.15, 1.3)
    phase = _TWO_PI * cadence * t + rng.uniform(0.0, _TWO_PI)
    for side, p in (("left", phase), ("right", phase + np.pi)):
        thigh = hip_mid + hip_amp * np.sin(p)  # forward angle of the thigh (rad)
        knee = knee_min + knee_amp * _bump(p + knee_peak)  # flexes most in early swing
        stance = 0.5 - 0.5 * np.cos(p)  # 1 at mid-stance, 0 at mid-swing
        flat = thigh - knee - lean  # ankle angle that keeps the sole level
        ankle = stance * flat + 0.3 * _bump(p + 1.3, 4.0) - 0.1 * (1.0 - stance)
        _set_side(euler, side, "hip", x=-thigh, z=0.03)
        _set_side(euler, side, "knee", x=knee)
        _set_side(euler, side, "ankle", x=ankle)
        _set_side(euler, side, "foot", x=-0.4 * _bump(p + 1.3, 4.0))
        arm = -swing * np.sin(p)  # forward swing of the arm, opposite to its leg
        _set_side(euler, side, "shoulder", y=-arm, z=-hang)
        _set_side(euler, side, "elbow", y=-(elbow + 0.3 * swing * (1.0 + np.sin(-p))))
    _set(euler, "pelvis", x=lean, y=-0.08 * np.sin(phase), z=0.03 * np.cos(phase))
    for name in ("spine2", "spine3"):
        _set(euler, name, x=0.03, y=0.05 * np.sin(phase))
    hop = rng.uniform(0.03, 0.07) * _bump(2.0 * phase - np.pi, 2.0) if running else None
    contact = 0.5 if running else 0.0  # |cos| above which one foot is on the ground
    stance = np.select([np.cos(phase) < -contact, np.cos(phase) > contact], [0, 1], -1)
    return _Plan(euler, yaw_rate=rng.uniform(-0.12, 0.12), hop=hop, stance=stance)


def _walk(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    return _gait(t, rng, running=False)


def _run(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    return _gait(t, rng, running=True)


def _arm_raise(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """One or both arms raised sideways above the head and lowered again, repeatedly."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    hang, top = rng.uniform(1.15, 1.3), rng.uniform(1.15, 1.45)
    sides = (("left",), ("right",), ("left", "right"))[rng.integers(3)]
    up = 0.5 - 0.5 * np.cos(_TWO_PI * t / rng.uniform(2.5, 4.0) + rng.uniform(0.0, _TWO_PI))
    forward = rng.uniform(0.0, 0.4)
    _hanging_arms(euler, hang)
    for side in sides:
        _set_side(euler, side, "collar", z=0.3 * up**2)
        _set_side(euler, side, "shoulder", y=-forward * up, z=-hang + (hang + top) * up)
        _set_side(euler, side, "elbow", y=-0.1 - 0.15 * (1.0 - up))
    if len(sides) == 1:  # lean a little away from the raised arm
        lean = 0.06 * up * (1.0 if sides[0] == "left" else -1.0)
        _set(euler, "spine2", z=lean)
        _set(euler, "spine3", z=lean)
    return _Plan(euler)


def _arm_swing(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """Arms swinging forward and back (alternating or together), or opening and closing in
    front of the chest."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    phase = _TWO_PI * rng.uniform(0.6, 1.1) * t + rng.uniform(0.0, _TWO_PI)
    mode = ("alternate", "together", "open_close")[rng.integers(3)]
    if mode == "open_close":
        closed = 0.5 - 0.5 * np.cos(phase)
        height = rng.uniform(0.0, 0.4)
        for side in ("left", "right"):
            _set_side(euler, side, "shoulder", y=0.3 - 1.6 * closed, z=-height)
            _set_side(euler, side, "elbow", y=-0.2 - 0.4 * closed)
        return _Plan(euler)
    hang, amp = rng.uniform(1.15, 1.3), rng.uniform(0.5, 1.0)
    for side, p in (("left", phase), ("right", phase + (np.pi if mode == "alternate" else 0.0))):
        forward = amp * np.sin(p)
        _set_side(euler, side, "shoulder", y=-forward, z=-hang)
        _set_side(euler, side, "elbow", y=-0.2 - 0.4 * _bump(p - np.pi / 2, 2.0))
    if mode == "alternate":
        for name in ("spine2", "spine3"):
            _set(euler, name, y=-0.08 * amp * np.sin(phase))
    return _Plan(euler)


def _torso_twist(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """The trunk turning left and right about the spine, arms hanging or held in front."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    twist = rng.uniform(0.4, 0.8) * np.sin(_TWO_PI * rng.uniform(0.3, 0.6) * t + rng.uniform(0, 7))
    for name, share in (("spine1", 0.25), ("spine2", 0.35), ("spine3", 0.4)):
        _set(euler, name, y=share * twist)
    _set(euler, "head", y=0.2 * twist)
    _set(euler, "pelvis", y=-0.1 * twist)
    if rng.random() < 0.5:
        hang = rng.uniform(1.15, 1.3)
        _hanging_arms(euler, hang)
        for side, sign in (("left", 1.0), ("right", -1.0)):  # both arms lag behind the trunk
            _set_side(euler, side, "shoulder", y=-0.3 * sign * twist, z=-hang)
    else:
        for side in ("left", "right"):
            _set_side(euler, side, "shoulder", y=-0.6, z=-0.9)
            _set_side(euler, side, "elbow", y=-1.5)
    return _Plan(euler)


def _torso_bend(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """Bending forward at the spine and hips and sideways, arms hanging."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    down = 0.5 - 0.5 * np.cos(_TWO_PI * rng.uniform(0.2, 0.4) * t + rng.uniform(0, _TWO_PI))
    spine = rng.uniform(0.5, 1.2) * down
    hips = rng.uniform(0.0, 0.5) * down
    side = rng.uniform(0.1, 0.35) * np.sin(
        _TWO_PI * rng.uniform(0.15, 0.35) * t + rng.uniform(0, 7)
    )
    for name in ("spine1", "spine2", "spine3"):
        _set(euler, name, x=spine / 3.0, z=side / 3.0)
    _set(euler, "pelvis", x=hips)
    hang = rng.uniform(1.15, 1.3)
    for s in ("left", "right"):
        _set_side(euler, s, "hip", x=-hips)  # legs stay vertical
        _set_side(euler, s, "shoulder", y=-0.8 * (spine + hips), z=-hang)  # arms hang down
        _set_side(euler, s, "elbow", y=-0.15)
    return _Plan(euler)


def _crouch(
    euler: np.ndarray,
    depth: np.ndarray,
    sides: tuple[str, ...],
    splay: object = 0.0,
    point: object = 0.0,
) -> None:
    """Bend the legs of ``sides`` into a crouch of ``depth`` ``(T,)`` (0 standing, ~1 a deep
    squat) with the soles level: thighs forward, shanks back, the pelvis and spine leaning
    forward; ``splay`` (rad) turns the knees outwards, ``point`` (rad) points the toes."""
    thigh, shank, pitch = 1.3 * depth, -0.55 * depth, 0.35 * depth  # world angles (rad)
    _set(euler, "pelvis", x=pitch)
    for s in sides:
        _set_side(euler, s, "hip", x=-thigh - pitch, z=splay)
        _set_side(euler, s, "knee", x=thigh - shank)
        _set_side(euler, s, "ankle", x=shank + point, z=-np.asarray(splay))
    for name in ("spine1", "spine2", "spine3"):
        _set(euler, name, x=0.08 * depth)


def _squat(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """Squats with flat feet: knees forward, hips back, trunk leaning, arms forward or down."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    depth_max = rng.uniform(0.6, 1.0)
    depth = depth_max * (
        0.5 - 0.5 * np.cos(_TWO_PI * rng.uniform(0.3, 0.5) * t + rng.uniform(0, 7))
    )
    _crouch(euler, depth, ("left", "right"), splay=0.15 * depth)
    hang = rng.uniform(1.15, 1.3)
    reach = depth / depth_max if rng.random() < 0.6 else np.zeros_like(depth)
    for s in ("left", "right"):
        _set_side(euler, s, "shoulder", y=-1.4 * reach, z=-hang * (1.0 - reach))
        _set_side(euler, s, "elbow", y=-0.2)
    return _Plan(euler)


def _jumping_jacks(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """Jumping jacks: jump the feet apart while the arms swing up over the head, then back."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    phase = _TWO_PI * rng.uniform(0.7, 1.0) * t + rng.uniform(0.0, _TWO_PI)
    out = 0.5 - 0.5 * np.cos(phase)
    hang, top, spread = rng.uniform(1.15, 1.3), rng.uniform(1.1, 1.4), rng.uniform(0.2, 0.32)
    knee = 0.1 + 0.25 * np.cos(phase) ** 2  # bent on the ground, straight in the air
    for s in ("left", "right"):
        _set_side(euler, s, "hip", x=-knee / 2, z=0.04 + spread * out)
        _set_side(euler, s, "knee", x=knee)
        _set_side(euler, s, "ankle", x=-knee / 2, z=-0.04 - spread * out)
        _set_side(euler, s, "collar", z=0.25 * out)
        _set_side(euler, s, "shoulder", z=-hang + (hang + top) * out)
        _set_side(euler, s, "elbow", y=-0.15)
    hop = rng.uniform(0.05, 0.12) * np.sin(phase) ** 2
    return _Plan(euler, hop=hop)


def _hop(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """Hopping in place, on both feet or on one: crouch, take off with the arms swinging
    forward and up, fly (the soles up to 8-20 cm), land into the next crouch."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    phase = _TWO_PI * rng.uniform(1.1, 1.6) * t + rng.uniform(0.0, _TWO_PI)
    crouch = rng.uniform(0.35, 0.7) * _bump(phase + np.pi / 2.0, 2.0)  # deepest before take-off
    flight = _bump(phase - np.pi / 2.0, 2.0)  # 1 at the top of the hop
    sides = ("left", "right")
    if rng.random() < 0.5:  # on one foot: the other thigh a little forward, knee bent
        lifted = sides[rng.integers(2)]
        _set_side(euler, lifted, "hip", x=-rng.uniform(0.1, 0.4))
        _set_side(euler, lifted, "knee", x=rng.uniform(0.9, 1.4))
        sides = tuple(s for s in sides if s != lifted)
    _crouch(euler, crouch, sides, splay=0.05, point=0.35 * flight)
    hang, swing = rng.uniform(1.15, 1.3), rng.uniform(0.4, 0.9)
    arm = swing * (flight - crouch / 0.7)  # forward and up in the air, back in the crouch
    for s in ("left", "right"):
        _set_side(euler, s, "shoulder", y=-arm, z=-hang * (1.0 - 0.3 * flight))
        _set_side(euler, s, "elbow", y=-0.3)
    return _Plan(euler, yaw_rate=rng.uniform(-0.2, 0.2), hop=rng.uniform(0.08, 0.2) * flight)


def _random_smooth(t: np.ndarray, rng: np.random.Generator) -> _Plan:
    """Every joint angle a sum of three random sinusoids about a random centre, saturated
    smoothly inside its limits; the heading turns slowly."""
    euler = np.zeros((t.size, NUM_JOINTS, 3))
    lo, hi = JOINT_LIMITS[1:, :, 0], JOINT_LIMITS[1:, :, 1]
    mid, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    centre = mid + half * rng.uniform(-0.3, 0.3, size=mid.shape)
    amp = half * rng.uniform(0.2, 0.6, size=mid.shape)
    weights = rng.uniform(0.2, 1.0, size=(3, *mid.shape))
    weights /= weights.sum(axis=0)
    freq = rng.uniform(0.1, 0.7, size=(3, *mid.shape))
    phase = rng.uniform(0.0, _TWO_PI, size=(3, *mid.shape))
    waves = np.sin(_TWO_PI * freq[:, None] * t[None, :, None, None] + phase[:, None])
    raw = centre + amp * np.einsum("kjc,ktjc->tjc", weights, waves)
    inner = 0.98 * half
    euler[:, 1:] = mid + inner * np.tanh((raw - mid) / inner)
    euler[:, 0] = 0.1 * np.sin(
        _TWO_PI * rng.uniform(0.1, 0.3, 3) * t[:, None] + rng.uniform(0, 7, 3)
    )
    return _Plan(euler, yaw_rate=rng.uniform(-0.3, 0.3))


_GENERATORS: dict[str, Callable[[np.ndarray, np.random.Generator], _Plan]] = {
    "walk": _walk,
    "run": _run,
    "arm_raise": _arm_raise,
    "arm_swing": _arm_swing,
    "torso_twist": _torso_twist,
    "torso_bend": _torso_bend,
    "squat": _squat,
    "jumping_jacks": _jumping_jacks,
    "random_smooth": _random_smooth,
    "hop": _hop,
}

#: The motion kinds :func:`make_motion` knows, with a one-line description each.
MOTION_KINDS: dict[str, str] = {
    "walk": "walking forward (+Z, slowly turning), arms swinging against the legs",
    "run": "running forward (+Z, slowly turning) with flight phases, elbows bent",
    "arm_raise": "one or both arms raised sideways over the head and lowered, repeatedly",
    "arm_swing": "arms swinging forward and back, or opening and closing in front of the chest",
    "torso_twist": "the trunk turning left and right, arms hanging or held in front",
    "torso_bend": "bending forward at the spine and hips and sideways, arms hanging",
    "squat": "squats with flat feet, hips back, arms forward or down",
    "jumping_jacks": "jumping the feet apart while the arms swing over the head, and back",
    "random_smooth": "every joint a smooth random trajectory within its limits, slow turning",
    "hop": "hopping in place on both feet or on one: crouch, take-off, flight, landing",
}


def random_betas(rng: np.random.Generator, sigma: float = 2.0) -> np.ndarray:
    """Random body shape: ``(10,)`` float32 betas, each standard normal clipped to ±``sigma``
    (each beta has unit variance over the body's population, so ±2 spans about 95% of it)."""
    return np.clip(rng.standard_normal(NUM_BETAS), -sigma, sigma).astype(np.float32)


def blend_in(t: np.ndarray, seconds: float = BLEND_SECONDS) -> np.ndarray:
    """Weights ``(T,)`` rising from 0 at ``t`` = 0 to 1 at ``seconds`` with the C² smootherstep
    ``6u⁵ − 15u⁴ + 10u³`` (zero velocity and acceleration at both ends)."""
    u = np.clip(np.asarray(t, dtype=np.float64) / seconds, 0.0, 1.0)
    return u**3 * (u * (6.0 * u - 15.0) + 10.0)


def make_motion(
    kind: str,
    frames: int,
    fps: float = 30.0,
    seed: int = 0,
    betas: np.ndarray | None = None,
    body: BodyModel | None = None,
    open_shoulders: bool = False,
) -> SmplMotion:
    """A procedural SMPL motion.

    Args:
        kind: one of :data:`MOTION_KINDS`.
        frames: number of frames T (≥ 1).
        fps: frames per second.
        seed: seed of the random amplitudes, frequencies and phases.
        betas: ``(≤10,)`` body shape (zero-padded), default the mean shape.
        body: the body the motion is made for (its soles keep the feet on the floor); default
            the embedded body.
        open_shoulders: open the shoulders sideways wherever an arm would come closer than
            :data:`ARM_CLEARANCE` to the torso (off: arms may press against the trunk).

    Returns:
        The motion: pose ``(T, 24, 3)`` axis-angle (rad) within the joint limits, trans
        ``(T, 3)`` (m), both float32, Y-up, the body facing +Z at the start; frame 0 is the rest
        pose with zero translation.

    Raises:
        ValueError: unknown kind, frames < 1, fps not positive, or bad betas.
    """
    if kind not in MOTION_KINDS:
        raise ValueError(f"unknown motion kind '{kind}' (one of: {', '.join(MOTION_KINDS)})")
    if frames < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    shape = np.zeros(NUM_BETAS, dtype=np.float32)
    if betas is not None:
        given = np.asarray(betas, dtype=np.float32).reshape(-1)
        if given.size > NUM_BETAS or not np.isfinite(given).all():
            raise ValueError(f"betas must be at most {NUM_BETAS} finite values")
        shape[: given.size] = given
    body = load_body_model() if body is None else body

    t = np.arange(frames) / fps
    weight = blend_in(t)
    plan = _GENERATORS[kind](t, np.random.default_rng(seed))
    pose = euler_to_pose(plan.euler * weight[:, None, None])
    if open_shoulders:
        pose = _open_shoulders(body, shape, pose, fps, weight=weight, limits=True)[0]
    heading = np.concatenate([[0.0], np.cumsum(plan.yaw_rate * weight[1:]) / fps])
    pose = clamp_to_limits(pose)
    root = Rotation.from_rotvec(heading[:, None] * [0.0, 1.0, 0.0]) * Rotation.from_rotvec(
        pose[:, 0]
    )
    pose[:, 0] = root.as_rotvec()

    soles = _sole_points(body, shape, pose)  # (T, S, 3), no translation
    trans = np.zeros((frames, 3))
    lift = soles[0, :, 1].min() - soles[:, :, 1].min(axis=1)  # keeps the lowest point down
    lift = gaussian_filter1d(lift, LIFT_SMOOTHING * fps)
    trans[:, 1] = lift - lift[0]
    if plan.hop is not None:
        trans[:, 1] += plan.hop * weight
    if plan.stance is not None:
        left = soles[0, :, 0] > 0.0  # the body's left is +X in the rest pose
        settled = t >= BLEND_SECONDS if np.count_nonzero(t >= BLEND_SECONDS) > 1 else t >= 0.0
        speed = _stance_speed(soles[settled], left, plan.stance[settled], heading[settled], fps)
        step = speed * weight / fps
        trans[1:, 0] = np.cumsum((step * np.sin(heading))[:-1])
        trans[1:, 2] = np.cumsum((step * np.cos(heading))[:-1])
    else:
        centre = soles[:, :, [0, 2]].mean(axis=1)
        trans[:, [0, 2]] = centre[0] - centre
    return SmplMotion(
        betas=shape,
        pose=pose.astype(np.float32),
        trans=trans.astype(np.float32),
        fps=float(fps),
        model=body.name,
    )


def arm_clearance(body: BodyModel, betas: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Distance (m) from each arm to the torso, per frame: ``(T, 2)`` (left, right) for
    ``pose`` ``(T, 24, 3)`` axis-angle on ``body`` at ``betas`` ``(10,)``.

    Arm vertices are those skinned mostly to a shoulder, elbow, wrist or hand joint and at
    least :data:`ARM_ROOT` from the torso in the rest pose; torso vertices those skinned mostly
    to the pelvis or the spine. Pose blendshapes included; the root translation does not matter.
    """
    dominant = body.weights.argmax(dim=1).numpy()
    torso = np.isin(dominant, [_J[name] for name in _TORSO_JOINTS])
    with torch.no_grad():
        out = body(torch.as_tensor(betas, dtype=torch.float32), torch.as_tensor(pose).float())
    rest = out.rest_vertices.reshape(-1, body.num_vertices, 3)[0].numpy()
    posed = out.vertices.numpy()
    arms = []
    for side in ("left", "right"):
        arm = np.isin(dominant, [_J[f"{side}_{part}"] for part in _ARM_JOINTS])
        arm[arm] = cKDTree(rest[torso]).query(rest[arm])[0] >= ARM_ROOT
        arms.append(arm)
    gaps = np.empty((len(pose), 2))
    for f in range(len(pose)):
        tree = cKDTree(posed[f, torso])
        for k, arm in enumerate(arms):
            points = posed[f, arm]
            # A bound from every 16th vertex prunes the exact search of all of them.
            bound = tree.query(points[::16])[0].min()
            gaps[f, k] = tree.query(points, distance_upper_bound=bound * (1 + 1e-6) + 1e-9)[0].min()
    return gaps


def arm_inside(body: BodyModel, betas: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Share of each arm's vertices inside the body, per frame: ``(T, 2)`` (left, right) in
    [0, 1] for ``pose`` ``(T, 24, 3)`` axis-angle on ``body`` at ``betas`` ``(10,)``.

    The arm vertices are those of :func:`arm_clearance`; a vertex is inside where its
    generalized winding number against the posed body without that arm's own faces (the faces
    touching a vertex skinned mostly to the arm's shoulder, elbow, wrist or hand) exceeds 0.5:
    an arm passing through the trunk, a thigh or the other arm. Arms resting against the
    body count as outside.
    """
    from usd_garment.eval.body_distance import WINDING_INSIDE, winding_numbers

    dominant = body.weights.argmax(dim=1).numpy()
    faces = body.faces.numpy()
    with torch.no_grad():
        out = body(torch.as_tensor(betas, dtype=torch.float32), torch.as_tensor(pose).float())
    rest = out.rest_vertices.reshape(-1, body.num_vertices, 3)[0].numpy()
    posed = out.vertices.double().numpy()
    torso = np.isin(dominant, [_J[name] for name in _TORSO_JOINTS])
    shares = np.empty((len(pose), 2))
    for s, side in enumerate(("left", "right")):
        limb = np.isin(dominant, [_J[f"{side}_{part}"] for part in _ARM_JOINTS])
        arm = limb.copy()
        arm[arm] = cKDTree(rest[torso]).query(rest[arm])[0] >= ARM_ROOT
        others = faces[~limb[faces].any(axis=1)]
        for f in range(len(pose)):
            shares[f, s] = np.mean(
                winding_numbers(posed[f, arm], posed[f], others) > WINDING_INSIDE
            )
    return shares


def open_shoulders(
    body: BodyModel,
    betas: np.ndarray,
    pose: np.ndarray,
    fps: float,
    clearance: float = ARM_CLEARANCE,
    *,
    weight: np.ndarray | None = None,
    limits: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Open the shoulders of ``pose`` wherever an arm comes closer than ``clearance`` to the
    torso (:func:`arm_clearance`).

    Each upper arm turns outwards about the forward axis (Z) of its parent's frame, the
    collar's: ``R_shoulder ← Rz(+a) · R_shoulder`` on the left, ``Rz(−a)`` on the right (the
    ``ez`` Euler angle of :mod:`usd_garment.motion.joint_limits`). The opening ``a`` of each side
    grows by :data:`ARM_STEP` rad at the frames still too close, spread over neighbouring
    frames (a running maximum over ±:data:`ARM_SMOOTHING` and a Gaussian), for at most
    :data:`ARM_STEPS` steps; where the arms are clear it stays zero.

    Args:
        body: the body model.
        betas: ``(10,)`` its shape.
        pose: ``(T, 24, 3)`` axis-angle (rad).
        fps: frame rate (the smoothing is in seconds).
        clearance: smallest distance (m) between an arm's vertices and the torso's.
        weight: ``(T,)`` factor on the opening (e.g. a blend-in from the rest pose); ones by
            default.
        limits: measure the clearance on the pose clamped to the joint limits
            (:func:`~usd_garment.motion.joint_limits.clamp_to_limits`), as it will be used.

    Returns:
        The opened pose ``(T, 24, 3)`` float64 (not clamped) and the opening ``(T, 2)`` (rad,
        ≥ 0, left and right).
    """
    pose = np.asarray(pose, dtype=np.float64)
    frames = len(pose)
    weight = np.ones(frames) if weight is None else np.asarray(weight, dtype=np.float64)
    need = np.zeros((frames, 2))
    lift = np.zeros((frames, 2))
    gaps = np.empty((frames, 2))
    opened = pose
    width = max(round(ARM_SMOOTHING * fps), 1)
    changed = np.arange(frames)
    for _ in range(ARM_STEPS):
        if changed.size:  # the other frames keep their pose and their clearance
            moved = opened[changed]
            gaps[changed] = arm_clearance(body, betas, clamp_to_limits(moved) if limits else moved)
        short = gaps < clearance
        if not short.any():
            break
        need += ARM_STEP * short
        spread = gaussian_filter1d(maximum_filter1d(need, 2 * width + 1, axis=0), width / 2, axis=0)
        new = spread * weight[:, None]
        changed = np.flatnonzero((new != lift).any(axis=1))
        lift = new
        opened = turn_shoulders(pose, lift)
    return opened, lift


_open_shoulders = open_shoulders  # make_motion's flag of the same name hides it


def turn_shoulders(pose: np.ndarray, lift: np.ndarray) -> np.ndarray:
    """``pose`` ``(T, 24, 3)`` with the left shoulder turned by ``Rz(lift[:, 0])`` and the right
    by ``Rz(−lift[:, 1])`` in their parents' frames (``lift`` ``(T, 2)`` rad)."""
    turned = pose.copy()
    for side, (name, sign) in enumerate((("left_shoulder", 1.0), ("right_shoulder", -1.0))):
        j = _J[name]
        rz = Rotation.from_rotvec(sign * lift[:, side, None] * [0.0, 0.0, 1.0])
        turned[:, j] = (rz * Rotation.from_rotvec(pose[:, j])).as_rotvec()
    return turned


def _sole_points(body: BodyModel, betas: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Posed sole points ``(T, S, 3)`` (m, no root translation, no pose blendshapes): the rest
    vertices of ``body`` at ``betas`` ``(10,)`` within :data:`SOLE_BAND` of the lowest one,
    skinned with ``pose`` ``(T, 24, 3)``."""
    with torch.no_grad():
        rest, joints = body.shaped(torch.as_tensor(betas)[None])
        height = rest[0, :, 1]
        sole = torch.nonzero(height < height.min() + SOLE_BAND).squeeze(1)
        rot = batch_rodrigues(torch.as_tensor(pose, dtype=torch.float32).reshape(-1, 3))
        rot = rot.reshape(-1, NUM_JOINTS, 3, 3)
        _, transforms = batch_rigid_transform(rot, joints.expand(len(pose), -1, -1), body.parents)
        points = skin(rest[:, sole].expand(len(pose), -1, -1), body.weights[sole], transforms)
    return points.double().numpy()


def _stance_speed(
    soles: np.ndarray, left: np.ndarray, stance: np.ndarray, heading: np.ndarray, fps: float
) -> float:
    """Average speed (m/s) at which the stance foot's sole points ``soles`` ``(T, S, 3)`` (those
    of the left foot where ``left`` ``(S,)``) move backwards along ``heading`` ``(T,)`` relative
    to the root while ``stance`` ``(T,)`` (0 left, 1 right, −1 none) says the foot is down: the
    speed that keeps it from sliding on average."""
    centres = np.stack([soles[:, left].mean(axis=1), soles[:, ~left].mean(axis=1)], axis=1)
    down = np.nonzero((stance[:-1] >= 0) & (stance[:-1] == stance[1:]))[0]
    if down.size == 0:
        return 0.0
    step = centres[down + 1, stance[down]] - centres[down, stance[down]]  # (K, 3)
    forward = step[:, 0] * np.sin(heading[down]) + step[:, 2] * np.cos(heading[down])
    return float(max(-forward.mean() * fps, 0.0))
