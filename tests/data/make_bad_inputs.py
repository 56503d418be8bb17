"""Rebuild the corpus of bad USD inputs in ``tests/data/bad/`` (from the repository root:
``python -m tests.data.make_bad_inputs``). Each file must make ``read_smpl_motion`` raise a
one-line ``UsdInputError``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom, UsdSkel, Vt

from tests.synthetic import TPOSE_JOINTS
from usd_garment.body.joints import SMPL_PARENTS, smpl_joint_paths

BAD = Path(__file__).parent / "bad"
JOINTS = smpl_joint_paths()
REST = TPOSE_JOINTS


def _matrices(positions: np.ndarray) -> Vt.Matrix4dArray:
    m = np.repeat(np.eye(4)[None], len(positions), axis=0)
    m[:, 3, :3] = positions
    return Vt.Matrix4dArray.FromNumpy(m)


def _skeleton(stage: Usd.Stage, joints: list[str], rest: np.ndarray) -> UsdSkel.Skeleton:
    UsdSkel.Root.Define(stage, "/Char")
    skel = UsdSkel.Skeleton.Define(stage, "/Char/Skel")
    skel.CreateJointsAttr(Vt.TokenArray(joints))
    skel.CreateBindTransformsAttr(_matrices(rest))
    parents = [SMPL_PARENTS[JOINTS.index(j)] for j in joints]
    local = rest.copy()
    for i, p in enumerate(parents):
        if p >= 0 and JOINTS[p] in joints:
            local[i] -= rest[joints.index(JOINTS[p])]
    skel.CreateRestTransformsAttr(_matrices(local))
    return skel


def _animation(stage: Usd.Stage, skel: UsdSkel.Skeleton, quats: np.ndarray, frames: int) -> None:
    anim = UsdSkel.Animation.Define(stage, "/Char/Skel/Anim")
    joints = list(skel.GetJointsAttr().Get())
    anim.CreateJointsAttr(Vt.TokenArray(joints))
    offsets = np.array(skel.GetRestTransformsAttr().Get())[:, 3, :3].astype(np.float32)
    rot, tr = anim.CreateRotationsAttr(), anim.CreateTranslationsAttr()
    for f in range(frames):
        rot.Set(Vt.QuatfArray.FromNumpy(quats.astype(np.float32)), f)
        tr.Set(Vt.Vec3fArray.FromNumpy(offsets), f)
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((len(joints), 3), np.float16)))
    binding = UsdSkel.BindingAPI.Apply(skel.GetPrim())
    binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])


def _stage() -> Usd.Stage:
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    return stage


def main() -> None:
    BAD.mkdir(exist_ok=True)
    identity = np.tile([0.0, 0.0, 0.0, 1.0], (len(JOINTS), 1))

    (BAD / "not_usd.usda").write_bytes(b"this is not a USD file\n\x00\x01\x02")

    good = _stage()
    _animation(good, _skeleton(good, JOINTS, REST), identity, 3)
    good.GetRootLayer().Export(str(BAD / "truncated.usdc"))
    data = (BAD / "truncated.usdc").read_bytes()
    (BAD / "truncated.usdc").write_bytes(data[: len(data) // 2])

    stage = _stage()
    UsdGeom.Xform.Define(stage, "/World")
    UsdGeom.Cube.Define(stage, "/World/Cube")
    stage.GetRootLayer().Export(str(BAD / "no_skeleton.usda"))

    stage = _stage()
    _skeleton(stage, JOINTS, REST)
    stage.GetRootLayer().Export(str(BAD / "no_animation.usda"))

    stage = _stage()
    keep = [j for j in JOINTS if not j.endswith(("left_knee", "right_elbow")) and "knee/" not in j]
    keep = [j for j in keep if "right_elbow/" not in j]
    rest = REST[[JOINTS.index(j) for j in keep]]
    _animation(stage, _skeleton(stage, keep, rest), identity[: len(keep)], 3)
    stage.GetRootLayer().Export(str(BAD / "missing_joints.usda"))

    stage = _stage()
    nan = identity.copy()
    nan[4] = np.nan
    _animation(stage, _skeleton(stage, JOINTS, REST), nan, 3)
    stage.GetRootLayer().Export(str(BAD / "nan_rotations.usda"))

    stage = _stage()
    _animation(stage, _skeleton(stage, JOINTS, REST), identity, 0)
    stage.GetRootLayer().Export(str(BAD / "zero_length.usda"))

    stage = _stage()
    _animation(stage, _skeleton(stage, JOINTS, REST), identity, 3)
    stage.SetStartTimeCode(10)
    stage.SetEndTimeCode(2)
    stage.GetRootLayer().Export(str(BAD / "end_before_start.usda"))


if __name__ == "__main__":
    main()
