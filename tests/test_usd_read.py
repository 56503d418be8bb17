"""Reading SMPL motion from USD: body layers, disguised rigs, and the bad-input corpus."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from pxr import Sdf, Usd, UsdSkel
from scipy.spatial.transform import Rotation

from tests.rigs import RigStyle, write_rig
from usd_garment.body.betas import MAX_ABS_BETA, as_betas
from usd_garment.body.model import BodyModel
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.body_layer import (
    ANIMATION_PATH,
    SKELETON_PATH,
    top_weights,
    write_body_layer,
)
from usd_garment.usd.errors import UsdInputError
from usd_garment.usd.joint_aliases import match_smpl_joints
from usd_garment.usd.read import find_skeletons, read_smpl_motion
from usd_garment.usd.stage import canonical_to_world_matrix

BAD = Path(__file__).parent / "data" / "bad"


def _motion(frames: int = 12, fps: float = 24.0, seed: int = 0) -> SmplMotion:
    rng = np.random.default_rng(seed)
    pose = rng.normal(scale=0.4, size=(frames, 24, 3)).astype(np.float32)
    pose[:, 22:] = 0.0  # SMPL-H style rigs have no hand joints
    trans = np.cumsum(rng.normal(scale=0.05, size=(frames, 3)), axis=0).astype(np.float32)
    betas = rng.normal(scale=0.5, size=10).astype(np.float32)
    return SmplMotion(betas, pose, trans, fps)


def _rotation_error(a: np.ndarray, b: np.ndarray) -> float:
    """Largest angle (rad) between axis-angle rotations ``(..., 3)``."""
    ra = Rotation.from_rotvec(a.reshape(-1, 3).astype(np.float64))
    rb = Rotation.from_rotvec(b.reshape(-1, 3).astype(np.float64))
    return float((ra.inv() * rb).magnitude().max())


def _vertices(body: BodyModel, m: SmplMotion) -> np.ndarray:
    with torch.no_grad():
        out = body(torch.as_tensor(m.betas), torch.as_tensor(m.pose), torch.as_tensor(m.trans))
    return out.vertices.double().numpy()


def _height(body: BodyModel) -> float:
    v = body.v_template.numpy()
    return float(v[:, 1].max() - v[:, 1].min())


def test_body_layer_round_trip(tmp_path: Path, body_model: BodyModel) -> None:
    motion = _motion()
    path = tmp_path / "body.usdc"
    write_body_layer(path, motion, body_model)
    back, info = read_smpl_motion(path, body_model)
    assert _rotation_error(back.pose, motion.pose) < 1e-5
    np.testing.assert_allclose(back.trans, motion.trans, atol=1e-5)
    np.testing.assert_allclose(back.betas, motion.betas, atol=1e-6)
    assert back.fps == motion.fps and back.num_frames == motion.num_frames
    assert (info.up_axis, info.meters_per_unit, info.default_prim) == ("Y", 1.0, "/Character")
    assert info.skeleton == SKELETON_PATH and info.skel_root == "/Character/Body"
    np.testing.assert_array_equal(info.canonical_to_world, np.eye(4))


def test_usdskel_skinning_matches_body_model(tmp_path: Path, synthetic_body: BodyModel) -> None:
    """USD's own skinning of the written mesh reproduces the body model's LBS (rigid weights)."""
    motion = _motion(frames=3)
    path = tmp_path / "body.usda"
    write_body_layer(path, motion, synthetic_body)
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/Character/Body"))
    cache.Populate(root, Usd.PrimDefaultPredicate)
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath(SKELETON_PATH)))
    skin_query = cache.GetSkinningQuery(stage.GetPrimAtPath("/Character/Body/Mesh"))
    rest = skin_query.GetPrim().GetAttribute("points").Get()
    expected = synthetic_body.v_template.numpy()  # no pose blendshapes in USD: compare without
    synthetic_no_pbs = BodyModel(
        synthetic_body.v_template.numpy(), synthetic_body.shapedirs.numpy(),
        np.zeros((expected.shape[0], 3, 0)), synthetic_body.J_regressor.numpy(),
        synthetic_body.weights.numpy(), synthetic_body.faces.numpy(),
    )  # fmt: skip
    verts = _vertices(synthetic_no_pbs, motion)
    for f, code in enumerate(motion.time_codes):
        xforms = skel_query.ComputeSkinningTransforms(Usd.TimeCode(float(code)))
        points = rest.__class__(rest)
        assert skin_query.ComputeSkinnedPoints(xforms, points, Usd.TimeCode(float(code)))
        np.testing.assert_allclose(np.array(points), verts[f], atol=1e-5)


def test_top_weights_renormalised() -> None:
    w = np.random.default_rng(0).dirichlet(np.ones(24), size=50)
    idx, top = top_weights(w)
    assert idx.shape == (50, 4) and np.allclose(top.sum(1), 1.0)
    assert np.all(np.diff(top, axis=1) <= 1e-7)
    np.testing.assert_allclose(top[:, 0], w.max(1) / np.sort(w, 1)[:, -4:].sum(1), rtol=1e-5)


@pytest.mark.parametrize(
    "style",
    [
        RigStyle(orient_seed=1),
        RigStyle(shuffle_seed=2, fingers=True),
        RigStyle(prefix="m_avg_", short_names=True, root_joint=True),
        RigStyle(up_axis="Z", meters_per_unit=0.01),
        RigStyle(
            up_axis="Z", meters_per_unit=0.01, step=5, orient_seed=3, shuffle_seed=4,
            prefix="m_avg_", short_names=True, root_joint=True, fingers=True,
        ),
    ],
    ids=["orient", "shuffle-fingers", "mavg-root", "zup-cm", "all-120fps"],
)  # fmt: skip
def test_disguised_rigs_give_the_same_motion(
    tmp_path: Path, body_model: BodyModel, style: RigStyle
) -> None:
    motion = _motion()
    plain_path, rig_path = tmp_path / "plain.usda", tmp_path / "rig.usda"
    write_rig(plain_path, motion, body_model, RigStyle())
    write_rig(rig_path, motion, body_model, style)
    plain, _ = read_smpl_motion(plain_path, body_model)
    rig, info = read_smpl_motion(rig_path, body_model)
    assert rig.num_frames == (motion.num_frames - 1) * style.step + 1
    assert info.time_codes_per_second == motion.fps * style.step
    rig.pose, rig.trans = rig.pose[:: style.step], rig.trans[:: style.step]
    assert _rotation_error(rig.pose, plain.pose) < 1e-5
    assert _rotation_error(plain.pose, motion.pose) < 1e-5
    tol = 1e-4 * _height(body_model)
    assert np.abs(_vertices(body_model, rig) - _vertices(body_model, motion)).max() < tol


def test_skelroot_transform_moves_the_body(tmp_path: Path, body_model: BodyModel) -> None:
    """A SkelRoot transform (here in a Z-up, centimetre stage) moves the body in the world."""
    motion = _motion()
    root = np.eye(4)
    root[:3, :3] = Rotation.from_euler("xyz", [10, 0, 40], degrees=True).as_matrix()
    root[3, :3] = [30.0, -20.0, 5.0]
    style = RigStyle(up_axis="Z", meters_per_unit=0.01, root_xform=root, orient_seed=5)
    path = tmp_path / "moved.usda"
    write_rig(path, motion, body_model, style)
    back, info = read_smpl_motion(path, body_model)
    to_world = canonical_to_world_matrix("Z", 0.01)
    np.testing.assert_allclose(info.canonical_to_world, to_world)

    def world(m: SmplMotion) -> np.ndarray:
        v = _vertices(body_model, m)
        return np.concatenate([v, np.ones((*v.shape[:-1], 1))], axis=-1) @ to_world

    error_m = np.abs(world(back) - world(motion) @ root).max() * 0.01
    assert error_m < 1e-4 * _height(body_model)


def test_sparse_samples_interpolate_like_usd(tmp_path: Path, body_model: BodyModel) -> None:
    motion = _motion(frames=4)
    path = tmp_path / "sparse.usda"
    write_rig(path, motion, body_model, RigStyle(step=4))
    back, _ = read_smpl_motion(path, body_model, frames=(2, 7))
    assert back.num_frames == 5 and back.time_codes.tolist() == [2, 3, 4, 5, 6]
    mid = 0.5 * (motion.trans[0] + motion.trans[1])  # time code 2 of 0..4: halfway (lerp)
    np.testing.assert_allclose(back.trans[0], mid, atol=1e-5)
    assert _rotation_error(back.pose[2], motion.pose[1]) < 1e-5  # time code 4 = sample 1


def test_betas_missing_warns_and_override(tmp_path: Path, body_model: BodyModel) -> None:
    motion = _motion(frames=2)
    path = tmp_path / "nobetas.usda"
    write_rig(path, motion, body_model, RigStyle(betas=False))
    with pytest.warns(UserWarning, match="smpl:betas"):
        back, _ = read_smpl_motion(path, body_model)
    np.testing.assert_array_equal(back.betas, np.zeros(10))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back, _ = read_smpl_motion(path, body_model, betas=motion.betas)
    np.testing.assert_allclose(back.betas, motion.betas)
    # trans follows the betas: the posed pelvis stays where the file puts it
    assert _rotation_error(back.pose, motion.pose) < 1e-5


def test_several_skeletons_need_a_choice(tmp_path: Path, body_model: BodyModel) -> None:
    a, b = tmp_path / "a.usda", tmp_path / "b.usda"
    write_body_layer(a, _motion(seed=1), body_model, with_mesh=False)
    write_body_layer(b, _motion(seed=2), body_model, with_mesh=False)
    scene = Usd.Stage.CreateNew(str(tmp_path / "scene.usda"))
    for name, src in (("A", a), ("B", b)):
        scene.DefinePrim(f"/{name}").GetReferences().AddReference(src.name)
    scene.GetRootLayer().Save()
    assert find_skeletons(scene) == ["/A/Body/Skeleton", "/B/Body/Skeleton"]
    with pytest.raises(UsdInputError, match=r"several animated skeletons.*/A/Body/Skeleton"):
        read_smpl_motion(tmp_path / "scene.usda", body_model)
    back, info = read_smpl_motion(tmp_path / "scene.usda", body_model, skeleton="/B/Body/Skeleton")
    assert _rotation_error(back.pose, _motion(seed=2).pose) < 1e-5
    assert info.skel_root == "/B/Body"
    with pytest.raises(UsdInputError, match="no Skeleton at"):
        read_smpl_motion(tmp_path / "scene.usda", body_model, skeleton="/C")


def test_sublayered_usdz_reads(tmp_path: Path, body_model: BodyModel) -> None:
    from pxr import Sdf, UsdUtils

    motion = _motion(frames=3)
    write_body_layer(tmp_path / "body.usdc", motion, body_model)
    top = Sdf.Layer.CreateNew(str(tmp_path / "shot.usda"))
    top.subLayerPaths.append("body.usdc")
    top.Save()
    assert UsdUtils.CreateNewUsdzPackage(str(tmp_path / "body.usdc"), str(tmp_path / "b.usdz"))
    for name in ("shot.usda", "b.usdz"):
        back, _ = read_smpl_motion(tmp_path / name, body_model)
        assert _rotation_error(back.pose, motion.pose) < 1e-5


def test_joint_aliases() -> None:
    names = ["root", "m_avg_Pelvis", "L_Hip", "right_hip", "Spine1", "LeftKnee", "knee_r"]
    names += ["spine2", "l_ankle", "R_Ankle", "spine3", "L_Foot", "R_Foot", "Neck"]
    names += ["smplx:left_collar", "R_Collar", "Head", "L_Shoulder", "R_Shoulder"]
    names += ["L_Elbow", "R_Elbow", "L_Wrist", "R_Wrist", "left_index1", "jaw"]
    index = match_smpl_joints([f"a/b/{n}" for n in names])
    assert index[0] == 1 and index[4] == 5 and index[5] == 6 and index[22] is None
    with pytest.raises(UsdInputError, match="missing SMPL joints: left_hip"):
        match_smpl_joints(names[:2] + names[3:])
    with pytest.raises(UsdInputError, match="both match SMPL joint 'left_hip'"):
        match_smpl_joints([*names, "Hip_L"])


@pytest.mark.parametrize("name", sorted(p.name for p in BAD.iterdir()))
def test_bad_inputs_give_one_line_errors(name: str, body_model: BodyModel) -> None:
    with pytest.raises(UsdInputError) as info:
        read_smpl_motion(BAD / name, body_model)
    message = str(info.value)
    assert message and "\n" not in message and name in message


def test_missing_file_and_bad_frames(tmp_path: Path, body_model: BodyModel) -> None:
    with pytest.raises(UsdInputError, match="no such file"):
        read_smpl_motion(tmp_path / "nope.usda", body_model)
    write_body_layer(tmp_path / "b.usda", _motion(frames=3), body_model, with_mesh=False)
    with pytest.raises(UsdInputError, match=r"frames 2\.\.9"):
        read_smpl_motion(tmp_path / "b.usda", body_model, frames=(2, 9))


def _static_layer(path: Path, motion: SmplMotion, body: BodyModel, with_range: bool) -> None:
    """A one-frame body layer turned into a static pose: the animation's rotations and
    translations as default values, no time samples; with or without the stage's time range."""
    write_body_layer(path, motion, body, with_mesh=False)
    layer = Sdf.Layer.FindOrOpen(str(path))
    for name in ("rotations", "translations"):
        spec = layer.GetAttributeAtPath(f"{ANIMATION_PATH}.{name}")
        value = layer.QueryTimeSample(spec.path, 0.0)
        for t in list(layer.ListTimeSamplesForPath(spec.path)):
            layer.EraseTimeSample(spec.path, t)
        spec.default = value
    if with_range:
        layer.startTimeCode, layer.endTimeCode = 0.0, 4.0
    else:
        layer.ClearStartTimeCode()
        layer.ClearEndTimeCode()
    layer.Save()


@pytest.mark.parametrize("with_range", [False, True], ids=["no-range", "range"])
def test_static_pose_reads(tmp_path: Path, body_model: BodyModel, with_range: bool) -> None:
    """Default values without time samples are a static pose: every frame of the stage's range,
    or one frame at time code 0 when the stage has none."""
    motion = _motion(frames=1)
    path = tmp_path / "static.usda"
    _static_layer(path, motion, body_model, with_range)
    back, info = read_smpl_motion(path, body_model)
    frames = 5 if with_range else 1
    assert back.num_frames == frames and back.time_codes.tolist() == list(range(frames))
    assert (info.start_time_code, info.end_time_code) == (0.0, frames - 1.0)
    assert _rotation_error(back.pose, np.repeat(motion.pose, frames, axis=0)) < 1e-5
    np.testing.assert_allclose(back.trans, np.repeat(motion.trans, frames, axis=0), atol=1e-5)


def _layer_with_motion(tmp_path: Path, body: BodyModel) -> tuple[Path, Sdf.Layer]:
    path = tmp_path / "b.usda"
    write_body_layer(path, _motion(frames=4), body, with_mesh=False)
    return path, Sdf.Layer.FindOrOpen(str(path))


def test_animation_without_translations(tmp_path: Path, body_model: BodyModel) -> None:
    """Rotations but no translations: UsdSkel would pose the rest transforms."""
    path, layer = _layer_with_motion(tmp_path, body_model)
    layer.GetPrimAtPath(ANIMATION_PATH).RemoveProperty(
        layer.GetAttributeAtPath(f"{ANIMATION_PATH}.translations")
    )
    layer.Save()
    with pytest.raises(UsdInputError, match=r"no animation: .*/Animation has no translations"):
        read_smpl_motion(path, body_model)


def test_blocked_sample_and_wrong_count(tmp_path: Path, body_model: BodyModel) -> None:
    path, layer = _layer_with_motion(tmp_path, body_model)
    rotations = Sdf.Path(f"{ANIMATION_PATH}.rotations")
    layer.SetTimeSample(rotations, 2.0, Sdf.ValueBlock())
    layer.Save()
    with pytest.raises(UsdInputError, match="has no rotations at time code 2"):
        read_smpl_motion(path, body_model)
    short = layer.QueryTimeSample(rotations, 1.0)[:20]
    layer.SetTimeSample(rotations, 2.0, short)
    layer.Save()
    with pytest.raises(UsdInputError, match="has 20 rotations for its 24 joints at time code 2"):
        read_smpl_motion(path, body_model)
    back, _ = read_smpl_motion(path, body_model, frames=(0, 2))  # only the frames read count
    assert back.num_frames == 2


def test_wrong_count_names_the_first_bad_time(body_model: BodyModel) -> None:
    for name in ("rotations", "translations", "scales"):
        with pytest.raises(UsdInputError, match=rf"has 23 {name} for its 24 joints at time code 1"):
            read_smpl_motion(BAD / f"wrong_count_{name}.usda", body_model)


def test_betas_beyond_the_shape_space(tmp_path: Path, body_model: BodyModel) -> None:
    with pytest.raises(UsdInputError, match=r"smpl:betas: betas\[0\] = 1e\+06 is outside"):
        read_smpl_motion(BAD / "huge_betas.usda", body_model)
    path = tmp_path / "b.usda"
    write_body_layer(path, _motion(frames=2), body_model, with_mesh=False)
    with pytest.raises(UsdInputError, match=r"betas given: betas\[1\] = -5\.5 is outside .* 5\)"):
        read_smpl_motion(path, body_model, betas=np.array([0.0, -5.5]))
    edge = np.array([MAX_ABS_BETA, -MAX_ABS_BETA] + [0.0] * 12 + [1e6, 0.0])  # 16: last 6 unused
    back, _ = read_smpl_motion(path, body_model, betas=edge)
    np.testing.assert_array_equal(back.betas, edge[:10])


def test_as_betas_bound() -> None:
    np.testing.assert_array_equal(as_betas([9.0]), [9.0] + [0.0] * 9)  # no bound by default
    with pytest.raises(ValueError, match=r"betas\[2\] = 7 is outside"):
        as_betas([0.0, 1.0, 7.0], max_abs=MAX_ABS_BETA)
    with pytest.raises(ValueError, match="NaN"):
        as_betas([np.nan], max_abs=MAX_ABS_BETA)
    assert as_betas([], max_abs=MAX_ABS_BETA).shape == (10,)
