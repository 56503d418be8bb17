"""Jumps of the root alone taken out of a motion: a teleport or a snapped heading within one
motion going on (a cut of :func:`~usd_garment.motion.cuts.root_cuts` that is no restart). Each
jump has the rigid map that takes the frames from it on to where the root would have gone
without it, so that what is smoothed or described over frames can go on across it as over the
motion without the jump, and be put back after.

Shapes: T frames, N points. Units: metres, radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from usd_garment.body.model import BodyModel
from usd_garment.motion.sequence import SmplMotion


@dataclass(frozen=True)
class RootJump:
    """A jump of the root alone into frame ``frame`` of a motion, with ``undo``, the rigid map
    ``(3, 4)`` row by row (m) that takes the posed frames from ``frame`` on to where the root's
    steps beside the jump, met midway, would have carried them (:meth:`at`)."""

    frame: int
    undo: tuple[float, ...]

    @classmethod
    def at(cls, frame: int, root: np.ndarray, cuts: Sequence[int] = ()) -> RootJump:
        """The jump into ``frame`` (0 < frame < T) of a motion whose root (pelvis) skinning
        transforms are ``root`` ``(T, 4, 4)``, its other ``cuts`` (frames) aside: the root
        expected at ``frame`` is the one at ``frame`` − 1 stepped on by the step midway between
        the root's steps before (``frame`` − 2 to ``frame`` − 1) and after (``frame`` to
        ``frame`` + 1) the jump, in the root's own frame; by the one of them that no cut or end
        of the motion leaves out, or by none."""
        before, after = frame - 1, frame + 1
        steps = []
        if before >= 1 and before not in cuts:
            steps.append(np.linalg.solve(root[before - 1], root[before]))
        if after < len(root) and after not in cuts:
            steps.append(np.linalg.solve(root[frame], root[after]))
        undo = root[before] @ _midway(steps) @ np.linalg.inv(root[frame])
        return cls(frame, tuple(undo[:3].reshape(-1).tolist()))


def _midway(steps: Sequence[np.ndarray]) -> np.ndarray:
    """``(4, 4)``: the rigid map midway between the rigid maps ``steps`` (none, one or two
    ``(4, 4)``): their translations' mean and the rotation halfway from one to the other."""
    if not steps:
        return np.eye(4)
    if len(steps) == 1:
        return steps[0]
    first, second = (Rotation.from_matrix(s[:3, :3]) for s in steps)
    middle = np.eye(4)
    half = Rotation.from_rotvec((first.inv() * second).as_rotvec() / 2)
    middle[:3, :3] = (first * half).as_matrix()
    middle[:3, 3] = (steps[0][:3, 3] + steps[1][:3, 3]) / 2
    return middle


def root_jumps(
    motion: SmplMotion, body: BodyModel, cuts: Sequence[int], restarts: Sequence[int]
) -> tuple[RootJump, ...]:
    """The jumps of the root alone of ``motion`` on ``body``: its ``cuts`` that are not
    ``restarts`` (frames; ``motion_cuts`` and ``motion_restarts``), each with the map that
    takes it out (:meth:`RootJump.at`)."""
    starts = set(restarts)
    frames = [k for k in cuts if k not in starts]
    if not frames:
        return ()
    root = root_transforms(motion, body)
    return tuple(RootJump.at(k, root, cuts) for k in frames)


def root_transforms(motion: SmplMotion, body: BodyModel) -> np.ndarray:
    """``(T, 4, 4)`` float64: the root's (pelvis's) skinning transforms of ``motion`` on
    ``body``, x ↦ R(x − J₀) + J₀ + trans, with J₀ the shaped body's rest pelvis joint (m)."""
    pelvis = _pelvis(motion, body)
    maps = np.broadcast_to(np.eye(4), (motion.num_frames, 4, 4)).copy()
    maps[:, :3, :3] = Rotation.from_rotvec(motion.pose[:, 0]).as_matrix()
    maps[:, :3, 3] = pelvis - maps[:, :3, :3] @ pelvis + motion.trans
    return maps


def _pelvis(motion: SmplMotion, body: BodyModel) -> np.ndarray:
    """``(3,)`` float64: J(β)₀ (m), the rest pelvis joint of ``body`` shaped by ``motion``'s
    betas, about which SMPL turns the root before adding ``trans``."""
    with torch.no_grad():
        _, joints = body.shaped(torch.as_tensor(motion.betas, dtype=torch.float32)[None])
    return joints[0, 0].double().numpy()


def jump_maps(count: int, jumps: Sequence[RootJump]) -> np.ndarray:
    """``(count, 4, 4)`` float64: for each frame of a motion, the rigid map (m) that takes its
    ``jumps`` (increasing frames) out: the identity before the first, and the jumps' maps
    composed in order after it (the frames after the second jump are taken to the first's
    run, then before it)."""
    maps = np.broadcast_to(np.eye(4), (count, 4, 4)).copy()
    for jump in jumps:
        undo = np.eye(4)
        undo[:3] = np.reshape(jump.undo, (3, 4))
        maps[jump.frame :] = maps[jump.frame - 1] @ undo
    return maps


def without_jumps(motion: SmplMotion, jumps: Sequence[RootJump], body: BodyModel) -> SmplMotion:
    """``motion`` with its ``jumps`` of the root alone taken out (:func:`jump_maps`): the root's
    rotation and translation from the first jump on moved as its skinning transform on
    ``body`` is, so that what a network sees goes on across each jump as the motion without it
    would (to the root's change of step there). The frames before the first jump are
    ``motion``'s own."""
    if not jumps:
        return motion
    pelvis = _pelvis(motion, body)
    start = jumps[0].frame
    maps = jump_maps(motion.num_frames, jumps)[start:]  # (T − start, 4, 4)
    turn, shift = maps[:, :3, :3], maps[:, :3, 3]
    pose, trans = motion.pose.copy(), motion.trans.copy()
    pose[start:, 0] = (
        Rotation.from_matrix(turn) * Rotation.from_rotvec(pose[start:, 0])
    ).as_rotvec()
    # R'(x − J₀) + J₀ + trans' = U(R(x − J₀) + J₀ + trans): trans' = U(trans + J₀) − J₀.
    trans[start:] = np.einsum("tab,tb->ta", turn, trans[start:] + pelvis) + shift - pelvis
    return replace(motion, pose=pose, trans=trans)


def mapped(maps: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The points ``(t, N, 3)`` (m) of each frame moved by its rigid map ``(t, 4, 4)``, in
    float64."""
    return np.einsum("tab,tnb->tna", maps[:, :3, :3], points) + maps[:, None, :3, 3]
