"""The stress suite's inputs: animated bodies where garment methods are known to fail: extreme
shapes (β₁ at ±3σ), motion played 2 and 4 times faster, a very long sequence, poses with
self-contact (forearms folded before the chest, wrists meeting at the midline; hands on the
hips), sudden root jumps, a splice of the joints alone (its cut declared, as an edit would;
found without it since stop 84), and real captures. Each is written as a body layer, as a user
would bring it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from usd_garment.body.joints import NUM_JOINTS, SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel
from usd_garment.eval.bench import BenchInput
from usd_garment.motion.bvh import load_bvh
from usd_garment.motion.joint_limits import clamp_to_limits, euler_to_pose
from usd_garment.motion.procedural import blend_in, make_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.body_layer import write_body_layer

#: Frames of every stress motion but the long one and the captures (30 fps).
STRESS_FRAMES = 90
#: Frames of the long sequence.
LONG_FRAMES = 10_000
_J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


def _held_pose(
    body: BodyModel, frames: int, arms: dict[str, tuple[float, float, float]]
) -> SmplMotion:
    """From the rest pose into the left-arm Euler angles ``arms`` (joint part → x, y, z rad;
    the right arm mirrored), eased in over the first second, then held while the trunk sways
    a little (±0.1 rad about the spine), at 30 fps."""
    fps = 30.0
    t = np.arange(frames) / fps
    euler = np.zeros((frames, NUM_JOINTS, 3))
    for part, (x, y, z) in arms.items():
        euler[:, _J[f"left_{part}"]] = (x, y, z)
        euler[:, _J[f"right_{part}"]] = (x, -y, -z)
    euler *= blend_in(t)[:, None, None]
    euler[:, _J["spine2"], 1] = 0.1 * np.sin(2.0 * np.pi * t / 2.5)
    pose = clamp_to_limits(euler_to_pose(euler))
    rest = make_motion("walk", 1, fps, body=body)  # feet on the floor at the origin
    trans = np.repeat(rest.trans, frames, axis=0)
    return SmplMotion(np.zeros(10, np.float32), pose.astype(np.float32),
                      trans.astype(np.float32), fps, model=body.name)  # fmt: skip


def _faster(motion: SmplMotion, factor: int) -> SmplMotion:
    """``motion`` played ``factor`` times faster at the same frame rate (every factor-th frame)."""
    return SmplMotion(motion.betas, motion.pose[::factor].copy(), motion.trans[::factor].copy(),
                      motion.fps, model=motion.model)  # fmt: skip


def _root_jumps(motion: SmplMotion) -> SmplMotion:
    """``motion`` with the root teleported 0.5 m sideways a third of the way in and its heading
    snapped by 90° two thirds of the way in (no transition frames)."""
    pose, trans = motion.pose.copy(), motion.trans.copy()
    t = motion.num_frames
    trans[t // 3 :, 0] += 0.5
    snap = Rotation.from_rotvec([0.0, np.pi / 2, 0.0])
    pose[2 * t // 3 :, 0] = (snap * Rotation.from_rotvec(pose[2 * t // 3 :, 0])).as_rotvec()
    return SmplMotion(motion.betas, pose, trans, motion.fps, model=motion.model)


def _joint_splice(walk: SmplMotion, other: SmplMotion) -> SmplMotion:
    """``walk`` whose joints take ``other``'s from half way in while its root walks on (an edit's
    splice no root jump shows), the cut declared there (``cut_times``, ``smpl:cuts``)."""
    half = walk.num_frames // 2
    pose = walk.pose.copy()
    pose[half:, 1:] = other.pose[half:, 1:]
    return SmplMotion(walk.betas, pose, walk.trans, walk.fps, model=walk.model,
                      cut_times=(float(walk.time_codes[half]),))  # fmt: skip


def stress_motions(
    body: BodyModel, long_frames: int = LONG_FRAMES
) -> dict[str, Callable[[], SmplMotion]]:
    """The procedural stress cases, name → a function making the motion (made on demand: the
    long one is large)."""
    walk = 2 * STRESS_FRAMES

    def shape(beta: float) -> Callable[[], SmplMotion]:
        return lambda: make_motion("walk", STRESS_FRAMES, seed=101, betas=[beta], body=body)

    return {
        "shape_beta1_plus3": shape(3.0),
        "shape_beta1_minus3": shape(-3.0),
        "fast_x2": lambda: _faster(make_motion("arm_swing", 2 * walk, seed=102, body=body), 2),
        "fast_x4": lambda: _faster(make_motion("arm_swing", 4 * walk, seed=102, body=body), 4),
        "arms_folded": lambda: _held_pose(
            body, STRESS_FRAMES, {"shoulder": (1.2, -1.2, -1.2), "elbow": (0.0, -1.8, 0.0)}
        ),
        "hands_on_hips": lambda: _held_pose(
            body, STRESS_FRAMES, {"shoulder": (0.9, 0.25, -0.95), "elbow": (0.0, -1.7, 0.0)}
        ),
        "root_jumps": lambda: _root_jumps(make_motion("walk", STRESS_FRAMES, seed=103, body=body)),
        "joint_splice": lambda: _joint_splice(
            make_motion("walk", STRESS_FRAMES, seed=103, body=body),
            make_motion("arm_raise", STRESS_FRAMES, seed=5, body=body),
        ),
        f"long_{long_frames}": lambda: make_motion("walk", long_frames, seed=104, body=body),
    }


def write_stress_inputs(
    folder: str | Path,
    body: BodyModel,
    *,
    long_frames: int = LONG_FRAMES,
    captures: Sequence[str | Path] = (),
    names: Sequence[str] | None = None,
) -> list[BenchInput]:
    """Write the stress cases (those in ``names``, default all) and each capture (BVH,
    imported at 30 fps with the importer's defaults) as body layers in ``folder``.

    Raises:
        ValueError: an unknown case name; BvhError, OSError: an unreadable capture.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    makers = stress_motions(body, long_frames)
    unknown = [n for n in names or () if n not in makers]
    if unknown:
        raise ValueError(f"unknown stress case '{unknown[0]}' (one of: {', '.join(makers)})")
    inputs = []
    for name, make in makers.items():
        if names is None or name in names:
            path = folder / f"{name}.usdc"
            write_body_layer(path, make(), body)
            inputs.append(BenchInput(name, path))
    for capture in captures:
        motion, _ = load_bvh(capture, body, fps=30.0)
        path = folder / f"capture_{Path(capture).stem}.usdc"
        write_body_layer(path, motion, body)
        inputs.append(BenchInput(path.stem, path))
    return inputs
