"""Rebuild the corpus of bad USD inputs in ``tests/data/bad/`` (from the repository root:
``python -m tests.data.make_bad_inputs``). Each file must make ``read_smpl_motion`` raise a
one-line ``UsdInputError``, and ``usd-garment dress`` fail with one ``Error:`` line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom, UsdSkel, Vt

from tests.synthetic import TPOSE_JOINTS
from usd_garment.body.joints import SMPL_PARENTS, smpl_joint_paths
from usd_garment.usd.schema import apply_smpl_body

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


def _wrong_count(name: str) -> Usd.Stage:
    """3 frames whose ``name`` attribute (rotations, translations or scales) holds one value
    fewer than the animation's joints at time code 1."""
    stage = _stage()
    _animation(stage, _skeleton(stage, JOINTS, REST), np.tile([0.0, 0.0, 0.0, 1.0], (24, 1)), 3)
    attr = stage.GetPrimAtPath("/Char/Skel/Anim").GetAttribute(name)
    if name == "scales":  # authored as a default: sample all frames, one short
        for f in range(3):
            attr.Set(Vt.Vec3hArray.FromNumpy(np.ones((len(JOINTS) - (f == 1), 3), np.float16)), f)
    else:
        attr.Set(attr.Get(1)[:-1], 1)
    return stage


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

    for name in ("rotations", "translations", "scales"):
        stage = _wrong_count(name)
        stage.GetRootLayer().Export(str(BAD / f"wrong_count_{name}.usda"))

    stage = _stage()
    skel = _skeleton(stage, JOINTS, REST)
    _animation(stage, skel, identity, 3)
    apply_smpl_body(skel.GetPrim(), np.array([1e6] + [0.0] * 9), "neutral", "default")
    stage.GetRootLayer().Export(str(BAD / "huge_betas.usda"))

    stage = _stage()
    skel = _skeleton(stage, JOINTS, REST)
    _animation(stage, skel, identity, 3)
    apply_smpl_body(skel.GetPrim(), np.zeros(10), "neutral", "default", cuts=(1.0, np.nan))
    stage.GetRootLayer().Export(str(BAD / "nan_cuts.usda"))

    stage = _stage()  # rotations and translations declared without samples or defaults
    _animation(stage, _skeleton(stage, JOINTS, REST), identity, 0)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(0)
    stage.GetRootLayer().Export(str(BAD / "no_animation_values.usda"))


if __name__ == "__main__":
    main()
