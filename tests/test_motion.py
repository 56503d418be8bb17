"""Joint limits and procedural motions: sign conventions checked with the body's forward pass,
determinism, limits, smooth starts from the rest pose, the body parts each kind moves, and the
``usd-garment motion`` command round trip through USD."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from usd_garment.body.joints import SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel, BodyOutput
from usd_garment.cli.main import main
from usd_garment.motion.joint_limits import (
    JOINT_LIMITS,
    clamp_to_limits,
    euler_to_pose,
    pose_to_euler,
    within_limits,
)
from usd_garment.motion.procedural import (
    ARM_CLEARANCE,
    BLEND_SECONDS,
    MOTION_KINDS,
    arm_clearance,
    blend_in,
    make_motion,
    open_shoulders,
    random_betas,
)
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.read import read_smpl_motion

J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}
FPS = 30.0
FRAMES = 90  # 3 s
MOCAP = Path("/work/shared/mocap")  # the shared CMU captures


def _posed(body: BodyModel, motion: SmplMotion) -> BodyOutput:
    with torch.no_grad():
        return body(
            torch.as_tensor(motion.betas),
            torch.as_tensor(motion.pose),
            torch.as_tensor(motion.trans),
        )


def _joints_for(body: BodyModel, joint: str, angles: tuple[float, float, float]) -> np.ndarray:
    """Posed joints ``(24, 3)`` with one joint at Euler ``angles`` (x, y, z), all else at rest."""
    euler = np.zeros((1, 24, 3))
    euler[0, J[joint]] = angles
    pose = torch.as_tensor(euler_to_pose(euler), dtype=torch.float32)
    with torch.no_grad():
        return body(torch.zeros(10), pose).joints[0].double().numpy()


@pytest.fixture(scope="module")
def motions(body_model: BodyModel) -> dict[str, SmplMotion]:
    return {kind: make_motion(kind, FRAMES, FPS, seed=3, body=body_model) for kind in MOTION_KINDS}


@pytest.fixture(scope="module")
def posed(body_model: BodyModel, motions: dict[str, SmplMotion]) -> dict[str, BodyOutput]:
    return {kind: _posed(body_model, m) for kind, m in motions.items()}


# --- conventions of joint_limits, checked on the body ----------------------------------------


def test_sign_conventions_on_the_body(body_model: BodyModel) -> None:
    rest = _joints_for(body_model, "pelvis", (0.0, 0.0, 0.0))
    up, fwd = 1, 2
    for side, s in (("left", 1.0), ("right", -1.0)):
        j = _joints_for(body_model, f"{side}_knee", (1.0, 0.0, 0.0))  # knee flexion: +x
        assert j[J[f"{side}_ankle"], fwd] < rest[J[f"{side}_ankle"], fwd] - 0.2
        j = _joints_for(body_model, f"{side}_hip", (-1.0, 0.0, 0.0))  # thigh forward: −x
        assert j[J[f"{side}_knee"], fwd] > rest[J[f"{side}_knee"], fwd] + 0.2
        j = _joints_for(body_model, f"{side}_hip", (0.0, 0.0, s * 0.5))  # abduction: ±z
        assert s * j[J[f"{side}_knee"], 0] > s * rest[J[f"{side}_knee"], 0] + 0.1
        j = _joints_for(body_model, f"{side}_ankle", (0.5, 0.0, 0.0))  # toes down: +x
        assert j[J[f"{side}_foot"], up] < rest[J[f"{side}_foot"], up] - 0.03
        j = _joints_for(body_model, f"{side}_shoulder", (0.0, 0.0, s * 1.2))  # raise: ±z
        assert j[J[f"{side}_wrist"], up] > rest[J[f"{side}_shoulder"], up] + 0.3
        j = _joints_for(body_model, f"{side}_shoulder", (0.0, -s * 1.0, 0.0))  # forward: ∓y
        assert j[J[f"{side}_wrist"], fwd] > rest[J[f"{side}_wrist"], fwd] + 0.3
        j = _joints_for(body_model, f"{side}_elbow", (0.0, -s * 1.5, 0.0))  # flexion: ∓y
        assert j[J[f"{side}_wrist"], fwd] > rest[J[f"{side}_wrist"], fwd] + 0.15
        j = _joints_for(body_model, f"{side}_collar", (0.0, 0.0, s * 0.4))  # shrug: ±z
        assert j[J[f"{side}_shoulder"], up] > rest[J[f"{side}_shoulder"], up] + 0.03
        j = _joints_for(body_model, f"{side}_wrist", (0.0, 0.0, -s * 0.8))  # palm-down bend
        assert j[J[f"{side}_hand"], up] < rest[J[f"{side}_hand"], up] - 0.03
    j = _joints_for(body_model, "spine1", (0.5, 0.0, 0.0))  # bend forward: +x
    assert j[J["head"], fwd] > rest[J["head"], fwd] + 0.15
    j = _joints_for(body_model, "spine1", (0.0, 0.4, 0.0))  # turn to the body's left: +y
    assert j[J["right_shoulder"], fwd] > rest[J["right_shoulder"], fwd] + 0.03
    j = _joints_for(body_model, "spine1", (0.0, 0.0, 0.3))  # lean to the body's right: +z
    assert j[J["head"], 0] < rest[J["head"], 0] - 0.1


def test_limits_are_mirrored_and_unique() -> None:
    for name in SMPL_JOINT_NAMES:
        if name.startswith("left_"):
            left, right = JOINT_LIMITS[J[name]], JOINT_LIMITS[J["right_" + name[5:]]]
            np.testing.assert_array_equal(right[0], left[0])
            np.testing.assert_array_equal(right[1:], -left[1:, ::-1])
    middle = np.where([n.endswith("_elbow") for n in SMPL_JOINT_NAMES], 2, 1)
    bounds = JOINT_LIMITS[np.arange(1, 24), middle[1:]]
    assert np.all(np.abs(bounds) < np.pi / 2)
    assert np.all(JOINT_LIMITS[1:, :, 0] < JOINT_LIMITS[1:, :, 1])


def test_euler_round_trip_and_clamp() -> None:
    rng = np.random.default_rng(0)
    lo, hi = JOINT_LIMITS[1:, :, 0], JOINT_LIMITS[1:, :, 1]
    euler = np.zeros((50, 24, 3))
    euler[:, 1:] = rng.uniform(lo, hi, size=(50, 23, 3))
    pose = euler_to_pose(euler)
    np.testing.assert_allclose(pose_to_euler(pose)[:, 1:], euler[:, 1:], atol=1e-9)
    assert within_limits(pose)
    np.testing.assert_allclose(clamp_to_limits(pose), pose, atol=1e-9)

    wild = rng.normal(0.0, 1.5, size=(50, 24, 3))
    assert not within_limits(wild)
    clamped = clamp_to_limits(wild)
    assert within_limits(clamped)
    np.testing.assert_array_equal(clamped[:, 0], wild[:, 0])  # the root is free


# --- procedural motions ----------------------------------------------------------------------


def test_blend_in_is_smooth_from_zero() -> None:
    t = np.linspace(0.0, 1.0, 101)
    w = blend_in(t)
    assert w[0] == 0.0 and np.all(w[t >= BLEND_SECONDS] == 1.0) and np.all(np.diff(w) >= 0)


@pytest.mark.parametrize("kind", list(MOTION_KINDS))
def test_motion_is_deterministic_valid_and_smooth(
    kind: str, body_model: BodyModel, motions: dict[str, SmplMotion]
) -> None:
    m = motions[kind]
    again = make_motion(kind, FRAMES, FPS, seed=3, body=body_model)
    np.testing.assert_array_equal(again.pose, m.pose)
    np.testing.assert_array_equal(again.trans, m.trans)
    other = make_motion(kind, FRAMES, FPS, seed=4, body=body_model)
    assert not np.allclose(other.pose, m.pose)

    assert m.pose.shape == (FRAMES, 24, 3) and m.trans.shape == (FRAMES, 3) and m.fps == FPS
    assert np.isfinite(m.pose).all() and np.isfinite(m.trans).all()
    assert within_limits(m.pose)
    # Starts at the rest T-pose, blends in with zero velocity.
    assert np.all(m.pose[0] == 0.0) and np.all(m.trans[0] == 0.0)
    assert np.abs(m.pose[1]).max() < 0.01 and np.abs(m.trans[1]).max() < 1e-3
    # Bounded joint angular acceleration (rad/s²) and root acceleration (m/s²).
    rot = Rotation.from_rotvec(m.pose.reshape(-1, 3).astype(np.float64))
    r = rot.as_matrix().reshape(FRAMES, 24, 3, 3)
    step = np.einsum("tjba,tjbc->tjac", r[:-1], r[1:]).reshape(-1, 3, 3)
    omega = Rotation.from_matrix(step).as_rotvec().reshape(FRAMES - 1, 24, 3) * FPS
    alpha = np.linalg.norm(np.diff(omega, axis=0), axis=-1) * FPS
    assert alpha.max() < 300.0
    assert np.linalg.norm(np.diff(m.trans, 2, axis=0), axis=-1).max() * FPS**2 < 30.0


@pytest.mark.parametrize("kind", list(MOTION_KINDS))
def test_feet_stay_on_the_floor(kind: str, posed: dict[str, BodyOutput]) -> None:
    low = posed[kind].vertices[..., 1].min(dim=1).values.double().numpy()
    floor = low[0]
    assert low.min() > floor - 0.015  # nothing sinks more than 1.5 cm into the floor
    if kind not in ("run", "jumping_jacks", "hop"):
        assert np.abs(low - floor).max() < 0.015  # and something always touches it


def test_walk_and_run_advance_with_alternating_feet(
    motions: dict[str, SmplMotion], posed: dict[str, BodyOutput]
) -> None:
    settled = int(BLEND_SECONDS * FPS)
    speeds = {}
    for kind in ("walk", "run"):
        trans = motions[kind].trans
        assert np.all(np.diff(trans[:, 2]) >= 0.0)
        speeds[kind] = (trans[-1, 2] - trans[settled, 2]) / ((FRAMES - 1 - settled) / FPS)
        assert abs(trans[-1, 0]) < 0.3 * trans[-1, 2]  # mostly along +Z
        joints = posed[kind].joints.numpy()
        ahead = joints[settled:, J["left_ankle"], 2] - joints[settled:, J["right_ankle"], 2]
        assert np.count_nonzero(np.diff(np.sign(ahead)) != 0) >= 3
    assert 0.8 < speeds["walk"] < 2.0 and 2.0 < speeds["run"] < 4.5
    assert motions["run"].trans[:, 1].max() > 0.01  # flight phases


def test_squat_lowers_the_pelvis_and_bends_the_knees(
    motions: dict[str, SmplMotion], posed: dict[str, BodyOutput]
) -> None:
    assert motions["squat"].trans[:, 1].min() < -0.12
    knees = pose_to_euler(motions["squat"].pose)[:, [J["left_knee"], J["right_knee"]], 0]
    assert knees.max() > 1.0
    joints = posed["squat"].joints.numpy()
    low = joints[:, J["pelvis"], 1].argmin()
    assert joints[low, J["left_knee"], 2] > joints[low, J["left_ankle"], 2] + 0.1  # knees forward


def test_arm_kinds_move_the_arms(posed: dict[str, BodyOutput]) -> None:
    j = posed["arm_raise"].joints.numpy()
    above = j[:, [J["left_wrist"], J["right_wrist"]], 1] - j[:, [J["left_shoulder"]], 1]
    assert above.max() > 0.3
    j = posed["jumping_jacks"].joints.numpy()
    both = np.minimum(j[:, J["left_wrist"], 1], j[:, J["right_wrist"], 1]) - j[:, J["head"], 1]
    assert both.max() > 0.1  # both wrists above the head at once
    spread = j[:, J["left_ankle"], 0] - j[:, J["right_ankle"], 0]
    assert spread.max() > spread[0] + 0.2
    j = posed["arm_swing"].joints.numpy()
    reach = j[:, [J["left_wrist"], J["right_wrist"]], 2] - j[:, [J["pelvis"]], 2]
    assert np.ptp(reach, axis=0).max() > 0.3


def test_torso_kinds_move_the_trunk(posed: dict[str, BodyOutput]) -> None:
    j = posed["torso_twist"].joints.numpy()
    line = j[:, J["left_shoulder"]] - j[:, J["right_shoulder"]]
    turn = np.arctan2(-line[:, 2], line[:, 0])  # rotation of the shoulder line about +Y
    assert np.ptp(turn) > 0.4
    j = posed["torso_bend"].joints.numpy()
    lean = j[:, J["neck"], 2] - j[:, J["pelvis"], 2]
    assert lean.max() > lean[0] + 0.15


def test_random_smooth_moves_most_joints(motions: dict[str, SmplMotion]) -> None:
    euler = pose_to_euler(motions["random_smooth"].pose)
    span = JOINT_LIMITS[1:, :, 1] - JOINT_LIMITS[1:, :, 0]
    assert np.mean(np.ptp(euler[:, 1:], axis=0) > 0.1 * span) > 0.8


def test_shoulders_open_on_request_to_keep_clear_of_a_heavy_torso(body_model: BodyModel) -> None:
    # β2 = 2 thickens torso and arms: the walk's hanging arms touch the trunk (about 1 mm apart
    # on the default body), as captured arms do; on request the shoulders open to leave room.
    betas = np.zeros(10, dtype=np.float32)
    betas[1] = 2.0
    hanging = make_motion("walk", 60, seed=1, betas=betas, body=body_model)
    assert arm_clearance(body_model, betas, hanging.pose).min() < ARM_CLEARANCE  # the default
    motion = make_motion("walk", 60, seed=1, betas=betas, body=body_model, open_shoulders=True)
    assert arm_clearance(body_model, betas, motion.pose).min() >= ARM_CLEARANCE
    euler = pose_to_euler(motion.pose)
    mean = pose_to_euler(hanging.pose)
    # The same plan, its arms hanging less low on the heavy body (left arm down is -z).
    assert euler[:, J["left_shoulder"], 2].min() > mean[:, J["left_shoulder"], 2].min() + 0.05
    assert euler[:, J["right_shoulder"], 2].max() < mean[:, J["right_shoulder"], 2].max() - 0.05
    assert np.abs(np.diff(euler[:, 1:], n=2, axis=0)).max() < 0.05  # still smooth


def test_open_shoulders_leaves_clear_arms_and_opens_about_the_collars_forward_axis(
    body_model: BodyModel,
) -> None:
    betas = np.zeros(10, dtype=np.float32)
    t_pose = np.zeros((3, 24, 3))
    pose, opening = open_shoulders(body_model, betas, t_pose, 30.0)  # arms clear: unchanged
    assert not opening.any()
    np.testing.assert_array_equal(pose, t_pose)
    hanging = np.zeros((3, 24, 3))
    hanging[:, J["left_shoulder"]] = [0.0, 0.0, -1.7]  # down, a little inwards
    hanging[:, J["right_shoulder"]] = [0.0, 0.0, 1.7]
    assert arm_clearance(body_model, betas, hanging).min() < 0.005  # touching
    pose, opening = open_shoulders(body_model, betas, hanging, 30.0, 0.005)
    assert arm_clearance(body_model, betas, pose).min() >= 0.005
    assert (opening > 0).all()
    np.testing.assert_allclose(pose[:, J["left_shoulder"], 2], -1.7 + opening[:, 0], atol=1e-9)
    np.testing.assert_allclose(pose[:, J["right_shoulder"], 2], 1.7 - opening[:, 1], atol=1e-9)
    others = [j for j in range(24) if j not in (J["left_shoulder"], J["right_shoulder"])]
    np.testing.assert_array_equal(pose[:, others], hanging[:, others])


def test_betas_and_bad_arguments(body_model: BodyModel) -> None:
    rng = np.random.default_rng(1)
    betas = random_betas(rng)
    assert betas.shape == (10,) and np.abs(betas).max() <= 2.0
    np.testing.assert_array_equal(betas, random_betas(np.random.default_rng(1)))
    m = make_motion("walk", 20, betas=betas[:4], body=body_model)
    np.testing.assert_array_equal(m.betas[:4], betas[:4])
    assert np.all(m.betas[4:] == 0) and m.trans[0].tolist() == [0.0, 0.0, 0.0]
    single = make_motion("run", 1, body=body_model)
    assert (
        single.pose.shape == (1, 24, 3) and np.all(single.pose == 0) and np.all(single.trans == 0)
    )
    for kwargs in ({"kind": "fly"}, {"frames": 0}, {"fps": 0.0}, {"betas": np.ones(11)}):
        args = {"kind": "walk", "frames": 10, "body": body_model, **kwargs}
        with pytest.raises(ValueError):
            make_motion(**args)  # type: ignore[arg-type]


# --- CLI -------------------------------------------------------------------------------------


def test_cli_make_writes_a_layer_that_reads_back(tmp_path: Path, body_model: BodyModel) -> None:
    out = tmp_path / "squat.usda"
    runner = CliRunner()
    result = runner.invoke(
        main, ["motion", "make", "squat", "-o", str(out), "--frames", "24", "--seed", "2",
               "--betas", "0.5,-1"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    expected = make_motion("squat", 24, 30.0, seed=2, betas=np.array([0.5, -1.0]), body=body_model)
    motion, _ = read_smpl_motion(out, body_model)
    assert motion.num_frames == 24 and motion.fps == 30.0
    np.testing.assert_allclose(motion.betas, expected.betas, atol=1e-6)
    diff = Rotation.from_rotvec(motion.pose.reshape(-1, 3)).inv() * Rotation.from_rotvec(
        expected.pose.reshape(-1, 3)
    )
    assert diff.magnitude().max() < 1e-4
    np.testing.assert_allclose(motion.trans, expected.trans, atol=1e-5)

    listed = runner.invoke(main, ["motion", "list"])
    assert listed.exit_code == 0 and all(kind in listed.output for kind in MOTION_KINDS)


@pytest.mark.parametrize(
    "args",
    [
        ["fly", "-o", "x.usda"],
        ["walk", "-o", "x.txt"],
        ["walk", "-o", "x.usda", "--betas", "1,a"],
        ["walk", "-o", "x.usda", "--betas", ",".join(["1"] * 11)],
        ["walk", "-o", "x.usda", "--frames", "0"],
        ["walk", "-o", "x.usda", "--body-model", "missing.npz"],
    ],
)
def test_cli_bad_input_is_one_line_and_writes_nothing(tmp_path: Path, args: list[str]) -> None:
    args = [str(tmp_path / a) if a.startswith(("x.", "missing")) else a for a in args]
    result = CliRunner().invoke(main, ["motion", "make", *args])
    assert result.exit_code != 0
    assert "Traceback" not in result.output and "Error" in result.output
    assert list(tmp_path.iterdir()) == []


# --- cuts: where smoothing over frames must stop ------------------------------------------------


def test_root_cuts_find_the_stress_suites_jumps_and_nothing_in_real_motion(
    motions: dict[str, SmplMotion], body_model: BodyModel
) -> None:
    """The stress suite's root jumps (0.5 m sideways at a third, the heading snapped by 90° at
    two thirds) are cuts, at the frames where they land; no procedural motion has one, nor the
    shared CMU captures at 30 frames/s (their roots' steps differ by at most about 0.02 m and
    0.25 rad from one to the next); a one-frame glitch of the root is a cut in and a cut out; a
    heading snapped by 60° is a cut at 30 frames/s, not at 5 (where a real turn may speed up
    that much from one step to the next)."""
    from usd_garment.eval.stress import _root_jumps
    from usd_garment.motion.bvh import read_bvh, retarget
    from usd_garment.motion.cuts import root_cuts

    for kind, motion in motions.items():
        assert root_cuts(motion) == (), kind
        assert root_cuts(_root_jumps(motion)) == (FRAMES // 3, 2 * FRAMES // 3), kind
    for clip in ("01", "02", "03"):
        capture, _ = retarget(read_bvh(MOCAP / f"cmu_131_{clip}.bvh"), body_model, arm_clearance=0)
        every = round(capture.fps / FPS)
        at_30 = SmplMotion(capture.betas, capture.pose[::every], capture.trans[::every], FPS)
        assert at_30.num_frames > 200 and root_cuts(at_30) == (), clip
    walk = motions["walk"]
    trans = walk.trans.copy()
    trans[40, 2] += 0.3
    assert root_cuts(SmplMotion(walk.betas, walk.pose, trans, FPS)) == (40, 41)
    pose = walk.pose.copy()
    snap = Rotation.from_rotvec([0.0, np.pi / 3, 0.0])
    pose[45:, 0] = (snap * Rotation.from_rotvec(pose[45:, 0])).as_rotvec()
    assert root_cuts(SmplMotion(walk.betas, pose, walk.trans, FPS)) == (45,)
    assert root_cuts(SmplMotion(walk.betas, pose, walk.trans, 5.0)) == ()
    assert root_cuts(SmplMotion(walk.betas, walk.pose[:2], walk.trans[:2], FPS)) == ()


def test_joint_cuts_find_splices_of_the_joints_and_nothing_in_real_motion(
    motions: dict[str, SmplMotion], body_model: BodyModel
) -> None:
    """A splice of the joints alone (the root walks on) is a cut where one step of the joints
    stands out from both beside it: the stress suite's (a walk taking an arm raise's joints
    half way in) undeclared, and CMU 131_02's joints taking 131_03's from frame 104, at 30 and
    at 120 frames/s. No procedural motion has one, nor the stress suite's 4x swing (whose steps
    all stand out alike), the shared captures at either rate, or the noisiest capture here (AMC
    01_08 at 120 frames/s); a joint thrown out for one frame and back is a glitch, not a cut."""
    from usd_garment.eval.stress import stress_motions
    from usd_garment.motion.bvh import load_bvh, read_bvh, retarget
    from usd_garment.motion.cuts import joint_cuts

    for kind, motion in motions.items():
        assert joint_cuts(motion) == (), kind
    stress = stress_motions(body_model)
    assert joint_cuts(stress["fast_x4"]()) == ()
    splice = replace(stress["joint_splice"](), cut_times=())
    assert joint_cuts(splice) == (splice.num_frames // 2,)
    captures = [
        retarget(read_bvh(MOCAP / f"cmu_131_0{n}.bvh"), body_model, arm_clearance=0)[0]
        for n in (2, 3)
    ]
    for every in (4, 1):  # 30 and 120 frames/s
        first, second = (
            SmplMotion(c.betas, c.pose[::every], c.trans[::every], c.fps / every) for c in captures
        )
        assert joint_cuts(first) == joint_cuts(second) == (), every
        at = 416 // every
        pose = first.pose.copy()
        pose[at:, 1:] = second.pose[at : len(pose), 1:]
        assert joint_cuts(replace(first, pose=pose)) == (at,), every
    amc, _ = load_bvh(Path("examples/mocap/asf/01_08.amc.xz"), body_model, arm_clearance=0)
    assert amc.fps == 120.0 and joint_cuts(amc) == ()
    walk = motions["walk"]
    glitch = walk.pose.copy()
    glitch[40, 16] += 1.5  # the left shoulder thrown out for one frame
    assert joint_cuts(replace(walk, pose=glitch)) == ()


def test_declared_cuts_land_on_the_first_frame_at_or_after_their_time_code(
    motions: dict[str, SmplMotion],
) -> None:
    """``cut_times`` (``smpl:cuts``, ``dress --cut``) are time codes: each cuts the first frame at
    or after it, beside the root's cuts; times at or before the first frame or past the last cut
    nothing; a two-frame motion, too short for ``root_cuts``, can be cut."""
    from usd_garment.motion.cuts import motion_cuts

    walk = motions["walk"]
    codes = np.arange(walk.num_frames) + 101.0
    at = SmplMotion(walk.betas, walk.pose, walk.trans, FPS, time_codes=codes)
    assert motion_cuts(at) == ()
    assert motion_cuts(replace(at, cut_times=(146.0,))) == (45,)
    assert motion_cuts(replace(at, cut_times=(145.5, 146.0))) == (45,)
    assert motion_cuts(replace(at, cut_times=(50.0, 101.0, codes[-1] + 0.5))) == ()
    trans = walk.trans.copy()
    trans[40, 2] += 0.3  # root cuts at 40 and 41
    assert motion_cuts(replace(at, trans=trans, cut_times=(146.0, 141.0))) == (40, 41, 45)
    two = SmplMotion(walk.betas, walk.pose[:2], walk.trans[:2], FPS, cut_times=(1.0,))
    assert motion_cuts(two) == (1,)
