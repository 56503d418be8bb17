"""BVH import: parsing and Euler conventions, joint mapping (CMU, Mixamo, SMPL names), rest
corrections, units, root translation, the shoulder opening that keeps the arms out of the trunk,
a real CMU clip through the CLI, and bad input."""

from __future__ import annotations

import gzip
import json
import lzma
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from usd_garment.body.joints import SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.motion.amass import ZUP_TO_YUP
from usd_garment.motion.bvh import (
    ARM_CONTACT_CLEARANCE,
    BvhClip,
    BvhError,
    BvhRetarget,
    BvhSkeleton,
    bone_angle_errors,
    forward_kinematics,
    is_bvh_path,
    leads_with_reference,
    load_bvh,
    map_joints,
    parse_bvh,
    read_bvh,
    retarget,
    up_rotation,
    world_motion,
)
from usd_garment.motion.capture_clip import read_text
from usd_garment.motion.procedural import arm_clearance, arm_inside
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.read import read_smpl_motion

CMU_CLIP = Path("/work/shared/mocap/cmu_131_01.bvh")
EXAMPLES_MOCAP = Path(__file__).parents[1] / "examples" / "mocap"
J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


@dataclass
class Joint:
    name: str
    parent: str | None
    offset: tuple[float, float, float]
    order: str = "ZYX"  # rotation channel order; the root also gets X/Y/Z position channels
    end: tuple[float, float, float] | None = None


def bvh_text(joints: list[Joint], angles: dict[str, np.ndarray], root_pos: np.ndarray,
             fps: float = 120.0) -> str:  # fmt: skip
    """A BVH file: ``angles[name]`` ``(T, 3)`` degrees in the joint's channel order (zero if
    absent), ``root_pos`` ``(T, 3)`` file units."""
    children: dict[str | None, list[Joint]] = {}
    for joint in joints:
        children.setdefault(joint.parent, []).append(joint)
    lines = ["HIERARCHY"]
    order: list[Joint] = []

    def emit(joint: Joint, depth: int) -> None:
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if joint.parent is None else 'JOINT'} {joint.name}")
        lines.append(pad + "{")
        lines.append(f"{pad}\tOFFSET {' '.join(f'{v:.6f}' for v in joint.offset)}")
        rot = " ".join(f"{a}rotation" for a in joint.order)
        pos = "Xposition Yposition Zposition " if joint.parent is None else ""
        lines.append(f"{pad}\tCHANNELS {6 if joint.parent is None else 3} {pos}{rot}")
        order.append(joint)
        for child in children.get(joint.name, []):
            emit(child, depth + 1)
        if joint.end is not None:
            end = " ".join(f"{v:.6f}" for v in joint.end)
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {end}", f"{pad}\t}}"])
        lines.append(pad + "}")

    emit(children[None][0], 0)
    frames = root_pos.shape[0]
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1.0 / fps:.6f}"]
    for t in range(frames):
        row = list(root_pos[t])
        for joint in order:
            row += list(angles.get(joint.name, np.zeros((frames, 3)))[t])
        lines.append(" ".join(f"{v:.6f}" for v in row))
    return "\n".join(lines) + "\n"


def mixamo_skeleton(rest: np.ndarray, cm: bool = True) -> list[Joint]:
    """Mixamo names, T-pose built from SMPL rest joints ``(24, 3)`` (m), in cm or m."""
    unit = 100.0 if cm else 1.0
    smpl_of = {
        "Hips": "pelvis", "Spine": "spine1", "Spine1": "spine2", "Spine2": "spine3",
        "Neck": "neck", "Head": "head",
    }  # fmt: skip
    parent_of = {"Hips": None, "Spine": "Hips", "Spine1": "Spine", "Spine2": "Spine1",
                 "Neck": "Spine2", "Head": "Neck"}  # fmt: skip
    for side, s in (("Left", "left"), ("Right", "right")):
        chain = [("UpLeg", "hip", "Hips"), ("Leg", "knee", "UpLeg"), ("Foot", "ankle", "Leg"),
                 ("ToeBase", "foot", "Foot"), ("Shoulder", "collar", "Spine2"),
                 ("Arm", "shoulder", "Shoulder"), ("ForeArm", "elbow", "Arm"),
                 ("Hand", "wrist", "ForeArm"), ("HandMiddle1", "hand", "Hand")]  # fmt: skip
        for name, smpl, parent in chain:
            smpl_of[side + name] = f"{s}_{smpl}"
            parent_of[side + name] = parent if parent == "Spine2" else side + parent
            if parent in ("Hips", "Spine2"):
                parent_of[side + name] = parent
    joints = []
    for name, parent in parent_of.items():
        here = rest[J[smpl_of[name]]]
        offset = here - (rest[J[smpl_of[parent]]] if parent else np.array([0.0, 0.0, 0.0]))
        end = (0.0, 0.18 * unit, 0.0) if name == "Head" else None
        joints.append(Joint(f"mixamorig:{name}", None if parent is None else f"mixamorig:{parent}",
                            tuple(offset * unit), "ZXY", end))  # fmt: skip
    return joints


def cmu_skeleton() -> list[Joint]:
    """CMU (cgspeed) names and rest pose, metres: legs spread 20°, arms horizontal, zero-length
    LHipJoint / LowerBack / Neck / LeftShoulder joints."""
    joints = [Joint("Hips", None, (0.0, 0.0, 0.0)),
              Joint("LowerBack", "Hips", (0.0, 0.0, 0.0)),
              Joint("Spine", "LowerBack", (0.0, 0.11, 0.0)),
              Joint("Spine1", "Spine", (0.0, 0.11, 0.0)),
              Joint("Neck", "Spine1", (0.0, 0.0, 0.0)),
              Joint("Neck1", "Neck", (0.0, 0.09, 0.0)),
              Joint("Head", "Neck1", (0.0, 0.09, 0.0), end=(0.0, 0.1, 0.0))]  # fmt: skip
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        l = side[0]  # noqa: E741
        joints += [
            Joint(f"{l}HipJoint", "Hips", (0.0, 0.0, 0.0)),
            Joint(f"{side}UpLeg", f"{l}HipJoint", (sign * 0.07, -0.09, 0.04)),
            Joint(f"{side}Leg", f"{side}UpLeg", (sign * 0.14, -0.39, 0.0)),
            Joint(f"{side}Foot", f"{side}Leg", (sign * 0.13, -0.37, 0.0)),
            Joint(f"{side}ToeBase", f"{side}Foot", (0.0, -0.02, 0.12), end=(0.0, 0.0, 0.06)),
            Joint(f"{side}Shoulder", "Spine1", (0.0, 0.0, 0.0)),
            Joint(f"{side}Arm", f"{side}Shoulder", (sign * 0.17, 0.08, 0.0), "ZXY"),
            Joint(f"{side}ForeArm", f"{side}Arm", (sign * 0.25, 0.0, 0.0), "ZXY"),
            Joint(f"{side}Hand", f"{side}ForeArm", (sign * 0.19, 0.0, 0.0), "ZXY"),
            Joint(f"{side}FingerBase", f"{side}Hand", (sign * 0.04, 0.0, 0.0), "ZXY",
                  end=(sign * 0.03, 0.0, 0.0)),
            Joint(f"{l}Thumb", f"{side}Hand", (0.0, 0.0, 0.0), "ZXY", end=(0.03, 0.0, 0.03)),
        ]  # fmt: skip
    return joints


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def smpl_rest(body: BodyModel) -> np.ndarray:
    with torch.no_grad():
        return body.shaped(torch.zeros(1, 10))[1][0].double().numpy()


def posed_joints(body: BodyModel, motion: SmplMotion) -> np.ndarray:
    with torch.no_grad():
        out = body(torch.as_tensor(motion.betas), torch.as_tensor(motion.pose),
                   torch.as_tensor(motion.trans))  # fmt: skip
    return out.joints.double().numpy()


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


# --------------------------------------------------------------------------------------------


def test_euler_channels_compose_in_the_listed_order() -> None:
    joints = [Joint("Hips", None, (0.0, 1.0, 0.0), "ZYX"),
              Joint("Spine", "Hips", (0.0, 0.2, 0.0), "XYZ", end=(0.0, 0.1, 0.0))]  # fmt: skip
    angles = {"Hips": np.array([[30.0, -20.0, 50.0]]), "Spine": np.array([[10.0, 70.0, -40.0]])}
    clip = parse_bvh(bvh_text(joints, angles, np.array([[1.0, 2.0, 3.0]])))
    rot, pos = forward_kinematics(clip)
    rz, ry, rx = (Rotation.from_euler(a, v, degrees=True).as_matrix()
                  for a, v in zip("zyx", (30.0, -20.0, 50.0), strict=True))  # fmt: skip
    hips = rz @ ry @ rx
    sx, sy, sz = (Rotation.from_euler(a, v, degrees=True).as_matrix()
                  for a, v in zip("xyz", (10.0, 70.0, -40.0), strict=True))  # fmt: skip
    np.testing.assert_allclose(rot[0, 0], hips, atol=1e-12)
    np.testing.assert_allclose(rot[0, 1], hips @ sx @ sy @ sz, atol=1e-12)
    np.testing.assert_allclose(pos[0, 0], [1.0, 2.0, 3.0])  # position channels replace OFFSET
    np.testing.assert_allclose(pos[0, 1], [1.0, 2.0, 3.0] + hips @ [0.0, 0.2, 0.0], atol=1e-12)
    assert clip.fps == 120.0


def mapped_names(skeleton: BvhSkeleton) -> dict[str, str]:
    return {n: skeleton.names[m] for n, m in zip(SMPL_JOINT_NAMES, map_joints(skeleton),
            strict=True) if m is not None}  # fmt: skip


def test_joint_mapping_by_name_and_structure(body_model: BodyModel) -> None:
    cmu = mapped_names(parse_bvh(bvh_text(cmu_skeleton(), {}, np.zeros((1, 3)))).skeleton)
    assert cmu["spine1"] == "LowerBack" and cmu["spine2"] == "Spine" and cmu["spine3"] == "Spine1"
    assert cmu["left_collar"] == "LeftShoulder" and cmu["left_shoulder"] == "LeftArm"
    assert cmu["left_wrist"] == "LeftHand" and cmu["left_hand"] == "LeftFingerBase"
    assert cmu["left_ankle"] == "LeftFoot" and cmu["left_foot"] == "LeftToeBase"
    assert cmu["neck"] == "Neck" and len(cmu) == 24
    mixamo_text = bvh_text(mixamo_skeleton(smpl_rest(body_model)), {}, np.zeros((1, 3)))
    mixamo = mapped_names(parse_bvh(mixamo_text).skeleton)
    assert mixamo["spine1"] == "mixamorig:Spine" and mixamo["spine3"] == "mixamorig:Spine2"
    assert mixamo["left_collar"] == "mixamorig:LeftShoulder"
    assert mixamo["left_hand"] == "mixamorig:LeftHandMiddle1" and len(mixamo) == 24
    # SMPL names (L_Shoulder is the shoulder, L_Foot the toe, L_Hand the hand)
    smpl_names = {"Hips": "Pelvis", "Spine": "Spine1", "Spine1": "Spine2", "Spine2": "Spine3",
                  "Neck": "Neck", "Head": "Head"}  # fmt: skip
    for side in ("Left", "Right"):
        for mixamo_name, smpl_name in (("UpLeg", "Hip"), ("Leg", "Knee"), ("Foot", "Ankle"),
                                       ("ToeBase", "Foot"), ("Shoulder", "Collar"),
                                       ("Arm", "Shoulder"), ("ForeArm", "Elbow"),
                                       ("Hand", "Wrist"), ("HandMiddle1", "Hand")):  # fmt: skip
            smpl_names[side + mixamo_name] = f"{side[0]}_{smpl_name}"
    text = mixamo_text
    for old, new in sorted(smpl_names.items(), key=lambda kv: -len(kv[0])):
        text = text.replace(f"mixamorig:{old}\n", f"m_avg_{new}\n")
    smpl = mapped_names(parse_bvh(text).skeleton)
    assert smpl == {n: f"m_avg_{smpl_names[m.split(':')[1]]}" for n, m in mixamo.items()}
    # the real CMU files name the collar LeftCollar and the shoulder LeftShoulder
    real = mapped_names(read_bvh(CMU_CLIP).skeleton)
    assert real["left_collar"] == "LeftCollar" and real["left_shoulder"] == "LeftShoulder"
    assert real["left_wrist"] == "LeftWrist" and real["left_hand"] == "LFingers"
    assert real["spine1"] == "lowerback" and real["spine3"] == "Chest2" and len(real) == 24


#: Bones whose direction the import reproduces exactly: each is moved by one BVH joint (the
#: collars' with ``collars="aimed"`` too, :data:`AIMED_BONES`; with ``"rest"``, the default,
#: they turn from SMPL's rest collars).
EXACT_BONES = (
    "left_hip>left_knee", "left_knee>left_ankle", "left_ankle>left_foot", "spine1>spine2",
    "spine2>spine3", "left_shoulder>left_elbow",
    "left_elbow>left_wrist", "left_wrist>left_hand", "right_hip>right_knee",
    "right_shoulder>right_elbow", "right_elbow>right_wrist",
)  # fmt: skip
#: Exact with ``collars="aimed"`` only.
AIMED_BONES = ("left_collar>left_shoulder", "right_collar>right_shoulder")


def bone_errors(
    clip: BvhClip, motion: SmplMotion, info: BvhRetarget, body: BodyModel
) -> dict[str, np.ndarray]:
    _, positions, _ = world_motion(clip, info.scale, up_rotation(info.up_axis))
    return bone_angle_errors(positions, posed_joints(body, motion), map_joints(clip.skeleton))


def test_rest_pose_gives_the_bvh_rest_bone_directions(body_model: BodyModel) -> None:
    real = read_bvh(CMU_CLIP)
    real.values = np.zeros((2, real.values.shape[1]))  # the file's rest pose
    synthetic = parse_bvh(bvh_text(cmu_skeleton(), {}, np.zeros((2, 3))))
    for clip in (real, synthetic):
        motion, info = retarget(clip, body_model, floor="capture", arm_clearance=None,
                                collars="aimed")  # fmt: skip
        errors = bone_errors(clip, motion, info, body_model)
        assert set(EXACT_BONES) | set(AIMED_BONES) <= set(errors)
        worst = {k: float(v.max()) for k, v in errors.items() if not k.startswith("pelvis>")}
        assert max(worst.values()) < 1e-3, worst
        # collars="rest" (the default): the rig's rest collars are SMPL's rest collars, the rest
        # still aimed
        motion, info = retarget(clip, body_model, floor="capture", arm_clearance=None)
        errors = bone_errors(clip, motion, info, body_model)
        worst = {k: float(v.max()) for k, v in errors.items()
                 if not k.startswith("pelvis>") and "collar>" not in k}  # fmt: skip
        assert max(worst.values()) < 1e-3, worst
        np.testing.assert_allclose(motion.pose[:, [J["left_collar"], J["right_collar"]]], 0.0,
                                   atol=1e-6)  # fmt: skip
    # the real CMU rest has the arms hanging down: so do SMPL's (T-pose arms turned by 90°)
    captured = retarget(real, body_model, arm_clearance=None)[0]
    joints = posed_joints(body_model, captured)[0]
    for side in ("left", "right"):
        arm = joints[J[f"{side}_elbow"]] - joints[J[f"{side}_shoulder"]]
        assert angle_deg(arm, np.array([0.0, -1.0, 0.0])) < 1.0
    # ... into the default body's wider trunk, until the shoulders open just enough
    betas = captured.betas
    assert arm_inside(body_model, betas, captured.pose).min() > 0.5
    opened, info = retarget(real, body_model)
    assert arm_inside(body_model, betas, opened.pose).max() < 0.03  # a hand grazing the thigh
    assert arm_clearance(body_model, betas, opened.pose).min() >= ARM_CONTACT_CLEARANCE
    assert 5.0 < info.opening_summary()["max_deg"] < 30.0


def test_collars_turn_from_the_rest_without_a_shrug(body_model: BodyModel) -> None:
    # CMU's collar bone rises from the middle of the chest, SMPL's falls from beside the neck:
    # aimed along the BVH's, the collars rise by about 30°, the shoulders 6-9 cm
    clip = read_bvh(CMU_CLIP)
    clip.values = clip.values[1:121]
    aimed, _ = retarget(clip, body_model, arm_clearance=None, collars="aimed")
    assert np.degrees(np.linalg.norm(aimed.pose[:, J["left_collar"]], axis=1)).min() > 25.0
    motion, _ = retarget(clip, body_model, arm_clearance=None, collars="rest")
    rest = smpl_rest(body_model)
    joints = posed_joints(body_model, motion)
    for side in ("left", "right"):
        collar = np.degrees(np.linalg.norm(motion.pose[:, J[f"{side}_collar"]], axis=1))
        assert collar.max() < 15.0, collar.max()  # the capture's own clavicle motion
        # the shoulder joint, along the chest's axis, within 3 cm of where SMPL's rest puts it
        # (8-9 cm higher before)
        up = joints[:, J["neck"]] - joints[:, J["spine3"]]
        up /= np.linalg.norm(up, axis=1, keepdims=True)
        rest_up = (rest[J["neck"]] - rest[J["spine3"]]) / np.linalg.norm(
            rest[J["neck"]] - rest[J["spine3"]])  # fmt: skip
        height = np.sum((joints[:, J[f"{side}_shoulder"]] - joints[:, J["spine3"]]) * up, axis=1)
        rest_height = float((rest[J[f"{side}_shoulder"]] - rest[J["spine3"]]) @ rest_up)
        assert np.abs(height - rest_height).max() < 0.03, (height.min(), height.max(), rest_height)
    # a BVH collar turned by 20° turns SMPL's by 20° (the upper arm keeps the BVH's direction)
    skeleton = cmu_skeleton()
    angles = {"LeftShoulder": np.array([[0.0, 0.0, 0.0], [20.0, 0.0, 0.0]])}  # ZYX: about Z
    synthetic = parse_bvh(bvh_text(skeleton, angles, np.zeros((2, 3))))
    turned, info = retarget(synthetic, body_model, floor="capture", arm_clearance=None,
                            collars="rest")  # fmt: skip
    collar = np.degrees(np.linalg.norm(turned.pose[:, J["left_collar"]], axis=1))
    np.testing.assert_allclose(collar, [0.0, 20.0], atol=1e-4)
    errors = bone_errors(synthetic, turned, info, body_model)
    assert errors["left_shoulder>left_elbow"].max() < 1e-3


def test_t_pose_rig_maps_to_the_zero_pose(body_model: BodyModel, tmp_path: Path) -> None:
    rest = smpl_rest(body_model)
    hips = (rest[0] + [0.0, 1.2, 0.0]) * 100.0  # cm
    path = write(tmp_path / "mixamo.bvh",
                 bvh_text(mixamo_skeleton(rest), {}, np.repeat(hips[None], 3, axis=0)))  # fmt: skip
    motion, info = load_bvh(path, body_model, floor="capture")
    assert info.units == "cm" and info.units_detected and info.scale == 0.01
    assert info.shoulder_opening is not None and not info.shoulder_opening.any()  # arms clear
    assert not info.unmapped and motion.fps == 120.0
    np.testing.assert_allclose(motion.pose, 0.0, atol=1e-5)
    np.testing.assert_allclose(motion.trans, [[0.0, 1.2, 0.0]] * 3, atol=1e-5)
    # the same rig facing -Z: the root turns 180° about Y, no joint twists
    flip = np.diag([-1.0, 1.0, -1.0])
    turned = [Joint(j.name, j.parent, tuple(flip @ j.offset), j.order, j.end)
              for j in mixamo_skeleton(rest)]  # fmt: skip
    motion, _ = retarget(parse_bvh(bvh_text(turned, {}, hips[None])), body_model)
    np.testing.assert_allclose(np.abs(motion.pose[0, 0]), [0.0, np.pi, 0.0], atol=1e-5)
    np.testing.assert_allclose(motion.pose[0, 1:], 0.0, atol=1e-5)
    # floor "body": the T-posed body stands on y = 0
    motion, info = load_bvh(path, body_model)
    with torch.no_grad():
        low = body_model(torch.as_tensor(motion.betas), torch.as_tensor(motion.pose),
                         torch.as_tensor(motion.trans)).vertices[..., 1].min()  # fmt: skip
    assert abs(float(low)) < 1e-5
    sole = float(body_model.v_template[:, 1].min())
    assert info.floor_shift_m == pytest.approx(-1.2 - sole, abs=1e-5)


def test_elbow_bend_and_random_poses_keep_bone_directions(body_model: BodyModel) -> None:
    rng = np.random.default_rng(0)
    skeleton = cmu_skeleton()
    frames = 5
    angles = {j.name: rng.uniform(-40.0, 40.0, (frames, 3)) for j in skeleton}
    angles["LeftForeArm"] = np.zeros((frames, 3))
    angles["LeftForeArm"][:, 2] = -90.0  # ZXY: bend forward about Y
    root = np.stack([np.linspace(0.0, 0.3, frames), np.full(frames, 0.95),
                     np.linspace(0.0, 1.0, frames)], axis=1)  # fmt: skip
    clip = parse_bvh(bvh_text(skeleton, angles, root))
    motion, info = retarget(clip, body_model, floor="capture", arm_clearance=None)
    assert info.units == "m" and not info.unmapped
    assert {"LHipJoint", "RHipJoint", "Neck1"} <= set(info.folded)
    assert {"LThumb", "RThumb"} == set(info.ignored)
    errors = bone_errors(clip, motion, info, body_model)
    for bone in EXACT_BONES:
        assert errors[bone].max() < 1e-3, (bone, errors[bone])
    aimed, info = retarget(clip, body_model, floor="capture", arm_clearance=None,
                           collars="aimed")  # fmt: skip
    errors = bone_errors(clip, aimed, info, body_model)
    for bone in (*EXACT_BONES, *AIMED_BONES):
        assert errors[bone].max() < 1e-3, (bone, errors[bone])
    joints = posed_joints(body_model, motion)
    upper = joints[:, J["left_elbow"]] - joints[:, J["left_shoulder"]]
    fore = joints[:, J["left_wrist"]] - joints[:, J["left_elbow"]]
    for t in range(frames):
        assert angle_deg(upper[t], fore[t]) == pytest.approx(90.0, abs=1e-3)
    elbow = np.degrees(np.linalg.norm(motion.pose[:, J["left_elbow"]], axis=1))
    np.testing.assert_allclose(elbow, 90.0, atol=3.0)  # up to the small rest corrections
    # the SMPL pelvis follows the BVH hips (J0 + trans = hips)
    np.testing.assert_allclose(joints[:, 0], root, atol=1e-5)


def test_units_and_up_axis_do_not_change_the_motion(body_model: BodyModel) -> None:
    rest = smpl_rest(body_model)
    rng = np.random.default_rng(1)
    frames = 4
    angles = {f"mixamorig:{n}": rng.uniform(-30.0, 30.0, (frames, 3))
              for n in ("Hips", "Spine1", "LeftArm", "RightLeg", "Neck")}  # fmt: skip
    root = np.stack([np.zeros(frames), np.full(frames, 1.1), np.linspace(0, 0.5, frames)], 1)
    cm = parse_bvh(bvh_text(mixamo_skeleton(rest), angles, root * 100.0))
    m = parse_bvh(bvh_text(mixamo_skeleton(rest, cm=False), angles, root))
    # Z-up: offsets and positions turned, rotations about the turned axes (Y→Z, Z→−Y)
    zup_joints = [Joint(j.name, j.parent, tuple(ZUP_TO_YUP.T @ j.offset), "YXZ",
                        None if j.end is None else tuple(ZUP_TO_YUP.T @ j.end))
                  for j in mixamo_skeleton(rest, cm=False)]  # fmt: skip
    zup_angles = {k: v * [-1.0, 1.0, 1.0] for k, v in angles.items()}
    zup = parse_bvh(bvh_text(zup_joints, zup_angles, root @ ZUP_TO_YUP))
    results = [retarget(c, body_model, arm_clearance=None) for c in (cm, m, zup)]
    assert [r[1].units for r in results] == ["cm", "m", "m"]
    assert [r[1].up_axis for r in results] == ["y", "y", "z"]
    for motion, _ in results[1:]:
        np.testing.assert_allclose(motion.pose, results[0][0].pose, atol=2e-5)
        np.testing.assert_allclose(motion.trans, results[0][0].trans, atol=2e-5)
    scaled, info = retarget(cm, body_model, scale=0.01, arm_clearance=None)
    assert info.units == "custom" and not info.units_detected
    np.testing.assert_allclose(scaled.pose, results[0][0].pose, atol=1e-6)
    # B. Hahne's conversion of the CMU database keeps CMU's unit, 1/0.45 inch.
    cmu_unit = 0.0254 / 0.45
    cmu = parse_bvh(bvh_text(mixamo_skeleton(rest / cmu_unit, cm=False), angles, root / cmu_unit))
    in_cmu_units, info = retarget(cmu, body_model, arm_clearance=None)
    assert info.units == "cmu" and info.units_detected
    np.testing.assert_allclose(in_cmu_units.trans, results[0][0].trans, atol=2e-5)
    tiny = parse_bvh(bvh_text(mixamo_skeleton(rest * 0.1, cm=False), {}, root * 0.1))
    with pytest.raises(BvhError, match="cannot tell the units"):
        retarget(tiny, body_model)


def test_real_cmu_clip_through_the_cli(body_model: BodyModel, tmp_path: Path) -> None:
    out = tmp_path / "walk.usda"
    args = ["import-bvh", str(CMU_CLIP), "-o", str(out), "--frames", "0:60", "--fps", "30"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "15 frames at 30 fps" in result.stdout and "units m (detected)" in result.stdout
    motion, _ = read_smpl_motion(out, body_model)
    assert motion.num_frames == 15 and motion.fps == 30.0
    direct, info = load_bvh(CMU_CLIP, body_model, fps=30.0, frames=(0, 60))
    angle = (Rotation.from_rotvec(motion.pose.reshape(-1, 3)).inv()
             * Rotation.from_rotvec(direct.pose.reshape(-1, 3))).magnitude()  # fmt: skip
    assert angle.max() < 1e-4
    np.testing.assert_allclose(motion.trans, direct.trans, atol=1e-5)
    # every 4th source frame is an output frame: the posed SMPL bones follow the BVH's
    clip = read_bvh(CMU_CLIP)
    _, positions, _ = world_motion(clip, info.scale, up_rotation(info.up_axis), slice(0, 60, 4))
    errors = bone_angle_errors(positions, posed_joints(body_model, motion),
                               map_joints(clip.skeleton))  # fmt: skip
    opened = np.degrees(info.shoulder_opening).max()
    assert opened > 1.0  # the arms hang into the default body's trunk: opened
    for bone in (*EXACT_BONES, "spine3>neck", "neck>head"):
        arm = bone.split(">")[0].endswith(("shoulder", "elbow", "wrist"))
        limit = opened + 0.01 if arm else 0.01  # the arm below the shoulder turns with it
        assert errors[bone].max() < limit, (bone, errors[bone].max())
    # walking forward (+Z) with the feet on the floor, head up
    joints = posed_joints(body_model, motion)
    assert joints[:, J["head"], 1].min() > 1.3 and joints[:, J["left_ankle"], 1].max() < 0.3

    result = CliRunner().invoke(main, ["import-bvh", str(CMU_CLIP), "-o", str(out), "--frames",
                                       "0:8", "--json", "--no-mesh"])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert '"frames": 8' in result.stdout and '"left_collar": "LeftCollar"' in result.stdout


def head_of(source: Path, frames: int, out: Path, first: int = 0) -> Path:
    """The BVH file ``out``: ``source``'s frames ``first`` to ``first + frames`` (exclusive)."""
    header, motion = read_text(source, "BVH").split("MOTION")
    lines = motion.strip().splitlines()  # "Frames: N", "Frame Time: t", then the frames
    rows = lines[2 + first : 2 + first + frames]
    return write(out, f"{header}MOTION\nFrames: {frames}\n{lines[1]}\n" + "\n".join(rows) + "\n")


def test_a_reference_pose_in_frame_0_is_left_out(body_model: BodyModel, tmp_path: Path) -> None:
    """CMU's BVH conversions add a T-pose as frame 0, from which the motion's first frame turns
    joints by 60-180 degrees (played at 30 fps it throws the cloth off the body, stop 81): the
    import leaves it out unless ``--frames`` keeps it; captures without one lose nothing."""
    clip = head_of(EXAMPLES_MOCAP / "cmu_13_39.bvh.xz", 12, tmp_path / "jump.bvh")
    parsed = read_bvh(clip)
    assert leads_with_reference(parsed)
    motion, info = retarget(parsed, body_model, arm_clearance=None)
    assert info.reference_left_out and motion.num_frames == 11
    without, _ = retarget(parsed, body_model, arm_clearance=None, frames=(1, 12))
    np.testing.assert_array_equal(motion.pose, without.pose)
    np.testing.assert_array_equal(motion.trans, without.trans)
    kept, kept_info = retarget(parsed, body_model, arm_clearance=None, frames=(0, 12))
    assert kept.num_frames == 12 and not kept_info.reference_left_out
    # the motion itself (frames 1 on) and a capture without a reference keep every frame
    rest = read_bvh(head_of(EXAMPLES_MOCAP / "cmu_13_39.bvh.xz", 11, tmp_path / "r.bvh", 1))
    assert not leads_with_reference(rest) and not leads_with_reference(read_bvh(CMU_CLIP))
    assert retarget(rest, body_model, arm_clearance=None)[0].num_frames == 11

    out = tmp_path / "jump.usda"
    result = CliRunner().invoke(main, ["import-bvh", str(clip), "-o", str(out), "--no-mesh"])
    assert result.exit_code == 0, result.output
    assert "11 frames at 120 fps" in result.stdout and "frame 0 left out" in result.stdout
    result = CliRunner().invoke(main, ["import-bvh", str(clip), "-o", str(out), "--no-mesh",
                                       "--frames", "0:12", "--json"])  # fmt: skip
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["frames"] == 12 and summary["reference_left_out"] is False


def swinging_arms(frames: int = 45, fps: float = 30.0) -> BvhClip:
    """CMU skeleton whose arms hang 60° below horizontal (clear of the body) for 0.5 s, then
    swing in to 95° (straight down and into the trunk) at 1 s and back out at 1.5 s."""
    t = np.arange(frames) / fps
    down = -60.0 - 35.0 * np.clip(np.sin(np.pi * (t - 0.5)), 0.0, None)
    zero = np.zeros(frames)
    angles = {"LeftArm": np.stack([down, zero, zero], axis=1),  # ZXY: Z first
              "RightArm": np.stack([-down, zero, zero], axis=1)}  # fmt: skip
    root = np.tile([0.0, 0.95, 0.0], (frames, 1))
    return parse_bvh(bvh_text(cmu_skeleton(), angles, root, fps=fps))


def test_shoulders_open_just_enough_smoothly_where_the_arms_enter_the_trunk(
    body_model: BodyModel,
) -> None:
    clip = swinging_arms()
    captured, off = retarget(clip, body_model, arm_clearance=None)
    assert off.arm_clearance_m is None and not off.shoulder_opening.any()
    betas = captured.betas
    assert arm_inside(body_model, betas, captured.pose[20:25]).max() > 0.5  # into the trunk
    motion, info = retarget(clip, body_model)
    assert info.arm_clearance_m == ARM_CONTACT_CLEARANCE
    assert arm_inside(body_model, betas, motion.pose[10::4]).max() == 0.0
    gaps = arm_clearance(body_model, betas, motion.pose)
    assert gaps.min() >= ARM_CONTACT_CLEARANCE and gaps.min() < 0.02  # still close: contact
    opening = info.shoulder_opening
    # nothing where the arms are clear (the first 0.2 s: the tail of the smoothing, < 0.03°),
    # left and right alike
    assert not opening[0].any() and opening[:6].max() < 5e-4
    np.testing.assert_allclose(motion.pose[:6], captured.pose[:6], atol=5e-4)
    np.testing.assert_allclose(opening[:, 0], opening[:, 1], atol=1e-6)
    # smooth: no step of the opening's ARM_STEP (0.05 rad) size between frames
    assert 0.2 < opening.max() < 0.7
    assert np.abs(np.diff(opening, 2, axis=0)).max() < 0.02
    # only the shoulders turn, outwards about the collar's forward axis
    changed = np.flatnonzero(np.abs(motion.pose - captured.pose).max(axis=(0, 2)) > 1e-6)
    assert [SMPL_JOINT_NAMES[j] for j in changed] == ["left_shoulder", "right_shoulder"]
    joints = posed_joints(body_model, motion)[20]
    before = posed_joints(body_model, captured)[20]
    assert joints[J["left_elbow"], 0] > before[J["left_elbow"], 0] + 0.02  # left is +X
    assert joints[J["right_elbow"], 0] < before[J["right_elbow"], 0] - 0.02


def test_arm_clearance_options_of_the_cli(tmp_path: Path) -> None:
    # four frames with the arms straight down, into the trunk
    source = write(tmp_path / "swing.bvh", bvh_text(
        cmu_skeleton(), {"LeftArm": np.tile([-95.0, 0.0, 0.0], (4, 1)),
                         "RightArm": np.tile([95.0, 0.0, 0.0], (4, 1))},
        np.tile([0.0, 0.95, 0.0], (4, 1))))  # fmt: skip
    runs = {}
    options = {"default": [], "wider": ["--arm-clearance", "0.02"],
               "zero": ["--arm-clearance", "0"], "off": ["--no-arm-correction"]}  # fmt: skip
    for name, extra in options.items():
        args = ["import-bvh", str(source), "-o", str(tmp_path / f"{name}.usda"), "--json"]
        result = CliRunner().invoke(main, args + extra)
        assert result.exit_code == 0, result.output
        runs[name] = json.loads(result.stdout)
    assert runs["default"]["arm_clearance_m"] == ARM_CONTACT_CLEARANCE
    assert runs["default"]["shoulder_opening"]["frames"] == 4
    assert 10.0 < runs["default"]["shoulder_opening"]["max_deg"] < 40.0
    wider = runs["wider"]["shoulder_opening"]["max_deg"]
    assert wider > runs["default"]["shoulder_opening"]["max_deg"] + 2.0
    for name in ("zero", "off"):
        assert runs[name]["arm_clearance_m"] is None
        assert runs[name]["shoulder_opening"] == {"mean_deg": 0.0, "max_deg": 0.0, "frames": 0}
    result = CliRunner().invoke(main, ["import-bvh", str(source), "-o",
                                       str(tmp_path / "t.usda")])  # fmt: skip
    assert "shoulders opened up to" in result.stdout and "to keep 5 mm clear" in result.stdout
    result = CliRunner().invoke(main, ["import-bvh", str(source), "-o", str(tmp_path / "n.usda"),
                                       "--arm-clearance", "-1"])  # fmt: skip
    assert result.exit_code == 2 and "--arm-clearance" in result.output


def test_compressed_files_read_as_the_plain_file(body_model: BodyModel, tmp_path: Path) -> None:
    """``.bvh.xz`` and ``.bvh.gz`` (how captures are kept in ``examples/mocap``) parse to the
    same clip as the plain file, through the command too; other names are not BVH files."""
    plain = read_bvh(CMU_CLIP)
    data = CMU_CLIP.read_bytes()
    for suffix, compress in ((".xz", lzma.compress), (".gz", gzip.compress)):
        packed = tmp_path / f"walk.bvh{suffix}"
        packed.write_bytes(compress(data))
        clip = read_bvh(packed)
        a, b = clip.skeleton, plain.skeleton
        assert a.names == b.names and a.channels == b.channels
        for got, want in ((a.parents, b.parents), (a.offsets, b.offsets),
                          (a.end_sites, b.end_sites), (clip.values, plain.values)):  # fmt: skip
            np.testing.assert_array_equal(got, want)
        assert clip.frame_time == plain.frame_time
        assert is_bvh_path(packed) and is_bvh_path(str(packed).upper())
    out = tmp_path / "walk.usda"
    args = ["import-bvh", str(tmp_path / "walk.bvh.xz"), "-o", str(out), "--frames", "0:8"]
    result = CliRunner().invoke(main, [*args, "--no-mesh"])
    assert result.exit_code == 0 and "8 frames at 120 fps" in result.stdout, result.output
    assert read_smpl_motion(out, body_model)[0].num_frames == 8
    assert is_bvh_path(CMU_CLIP)
    assert not any(is_bvh_path(name) for name in ("walk.usda", "walk.xz", "bvh.gz", "walk.usd.gz"))


def _not_xz(tmp: Path) -> Path:
    return write(tmp / "walk.bvh.xz", CMU_CLIP.read_text()[:2000])


def _cut_gz(tmp: Path) -> Path:
    (tmp / "walk.bvh.gz").write_bytes(gzip.compress(CMU_CLIP.read_bytes())[:5000])
    return tmp / "walk.bvh.gz"


def _truncated(tmp: Path) -> Path:
    lines = CMU_CLIP.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Frame Time"))
    return write(tmp / "truncated.bvh", "\n".join(lines[: start + 11]) + "\n0.1 0.2")


def _binary(tmp: Path) -> Path:
    (tmp / "bin.bvh").write_bytes(bytes(range(256)))
    return tmp / "bin.bvh"


def _armless(tmp: Path) -> Path:
    joints = [j for j in cmu_skeleton() if not j.name.startswith("Left")
              or j.name.startswith(("LeftUp", "LeftLeg", "LeftFoot", "LeftToe"))]  # fmt: skip
    return write(tmp / "armless.bvh", bvh_text(joints, {}, np.zeros((2, 3))))


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (lambda t: write(t / "notes.bvh", "hello, not a capture\n"), "not a BVH file"),
        (_binary, "not a BVH file"),
        (lambda t: write(t / "empty.bvh", ""), "not a BVH file"),
        (_truncated, "truncated MOTION section"),
        (_armless, "lacks SMPL joints: left_shoulder, left_elbow, left_wrist"),
        (lambda t: write(t / "open.bvh", "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n"),
         "no MOTION section"),
        (lambda t: write(t / "open2.bvh", "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nMOTION\n"),
         "HIERARCHY is incomplete"),
        (lambda t: write(t / "zero.bvh", bvh_text(cmu_skeleton(), {}, np.zeros((1, 3)))
                         .replace("Frame Time: 0.008333", "Frame Time: 0")),
         "Frame Time must be positive"),
        (lambda t: write(t / "nan.bvh", bvh_text(cmu_skeleton(), {}, np.full((2, 3), np.nan))),
         "NaN"),
        (lambda t: t / "missing.bvh", "missing.bvh: no such file"),
        (_not_xz, "walk.bvh.xz: not a valid xz-compressed file"),
        (_cut_gz, "walk.bvh.gz: not a valid gzip-compressed file"),
    ],
    ids=["text", "binary", "empty", "truncated", "armless", "no-motion", "open-hierarchy",
         "zero-frame-time",
         "nan", "missing", "not-xz", "cut-gz"],
)  # fmt: skip
def test_bad_input_gives_one_line_and_no_output(
    tmp_path: Path, make: Callable[[Path], Path], expected: str
) -> None:
    source = make(tmp_path)
    before = sorted(tmp_path.iterdir())
    result = CliRunner().invoke(main, ["import-bvh", str(source), "-o", str(tmp_path / "b.usda")])
    assert result.exit_code == 1
    message = result.stderr.strip()
    assert message.startswith("Error:") and "\n" not in message, message
    assert expected in message, message
    assert sorted(tmp_path.iterdir()) == before  # no output, no temporary file left


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["-o", "{dir}/b.obj"], "must end in one of"),
        (["-o", "{dir}/none/b.usda"], "does not exist"),
        (["-o", "{dir}/b.usda", "--frames", "50:999"], "outside the file's 0:60"),
        (["-o", "{dir}/b.usda", "--betas", "1,9"], "outside the body's shape space"),
    ],
)
def test_bad_arguments(tmp_path: Path, extra: list[str], expected: str) -> None:
    lines = CMU_CLIP.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Frames:"))
    lines[start] = "Frames: 60"
    source = write(tmp_path / "short.bvh", "\n".join(lines[: start + 62]) + "\n")
    before = sorted(tmp_path.iterdir())
    args = ["import-bvh", str(source)] + [a.format(dir=tmp_path) for a in extra]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1
    message = result.stderr.strip()
    assert message.startswith("Error:") and "\n" not in message and expected in message, message
    assert sorted(tmp_path.iterdir()) == before
