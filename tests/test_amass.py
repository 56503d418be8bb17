"""AMASS npz in and out: frame change about the pelvis, resampling, and the CLI round trip."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from usd_garment.body.io import load_body_model, save_body_model
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.motion.amass import ZUP_TO_YUP, AmassError, load_amass, save_amass
from usd_garment.motion.resample import resample_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.read import read_smpl_motion


def _amass_npz(path: Path, frames: int = 20, fps: float = 60.0) -> dict[str, np.ndarray]:
    """A Z-up AMASS-style file: left shoulder raise, right knee bend, a turn and a walk."""
    t = np.linspace(0.0, 1.0, frames)
    poses = np.zeros((frames, 156))
    stand = Rotation.from_euler("x", 90, degrees=True)  # SMPL Y-up body standing in Z-up
    turn = Rotation.from_euler("z", 60 * t[:, None], degrees=True)
    poses[:, :3] = (turn * stand).as_rotvec()
    poses[:, 16 * 3 + 2] = -1.2 * t  # left shoulder: raise the arm about Z
    poses[:, 5 * 3] = 1.4 * t  # right knee bend about X
    trans = np.stack([0.8 * t, 1.1 * t, 0.9 + 0.02 * np.sin(6 * t)], axis=1)
    data = {
        "poses": poses,
        "trans": trans,
        "betas": np.linspace(-1.0, 1.0, 16),
        "gender": np.array("female"),
        "mocap_framerate": np.array(fps),
    }
    np.savez(path, **data)
    return data


def _posed(body: BodyModel, m: SmplMotion) -> torch.Tensor:
    with torch.no_grad():
        return body(torch.as_tensor(m.betas), torch.as_tensor(m.pose), torch.as_tensor(m.trans))


def test_zup_to_yup_moves_the_body_rigidly(tmp_path: Path, body_model: BodyModel) -> None:
    data = _amass_npz(tmp_path / "a.npz")
    motion = load_amass(tmp_path / "a.npz", body_model)
    assert motion.fps == 60.0 and motion.gender == "female" and motion.num_frames == 20
    np.testing.assert_allclose(motion.betas, data["betas"][:10], atol=1e-6)
    zup = SmplMotion(motion.betas, np.zeros_like(motion.pose), data["trans"].astype(np.float32), 60)
    zup.pose[:, :22] = data["poses"][:, :66].reshape(-1, 22, 3)
    z_vertices = _posed(body_model, zup).vertices.double().numpy()
    y_vertices = _posed(body_model, motion).vertices.double().numpy()
    np.testing.assert_allclose(y_vertices, z_vertices @ ZUP_TO_YUP.T, atol=2e-5)
    # The body stands up along +Y in the canonical frame.
    joints = _posed(body_model, motion).joints[0].numpy()
    assert joints[15, 1] > joints[0, 1] > joints[7, 1]


def test_resample_slerps_and_lerps() -> None:
    rng = np.random.default_rng(0)
    pose = rng.normal(scale=0.5, size=(5, 24, 3)).astype(np.float32)
    trans = rng.normal(size=(5, 3)).astype(np.float32)
    motion = SmplMotion(np.zeros(10, np.float32), pose, trans, 10.0)
    up = resample_motion(motion, 20.0)
    assert up.num_frames == 9 and up.fps == 20.0
    np.testing.assert_allclose(up.trans[::2], trans, atol=1e-6)
    np.testing.assert_allclose(up.trans[1], 0.5 * (trans[0] + trans[1]), atol=1e-6)
    r0, r1 = Rotation.from_rotvec(pose[0]), Rotation.from_rotvec(pose[1])
    half = r0 * Rotation.from_rotvec(0.5 * (r0.inv() * r1).as_rotvec())
    assert (half.inv() * Rotation.from_rotvec(up.pose[1])).magnitude().max() < 1e-5
    down = resample_motion(motion, 4.0)
    assert down.num_frames == 2
    np.testing.assert_allclose(down.trans[1], 0.5 * (trans[2] + trans[3]), atol=1e-6)


def test_import_export_round_trip(tmp_path: Path, body_model: BodyModel) -> None:
    """npz (Z-up) → import-amass → USD → read back and export-amass: same poses and trans."""
    data = _amass_npz(tmp_path / "walk.npz")
    save_body_model(tmp_path / "body.npz", body_model)
    args = ["--body-model", str(tmp_path / "body.npz")]
    runner = CliRunner()
    usd = tmp_path / "walk.usda"
    result = runner.invoke(
        main, ["import-amass", str(tmp_path / "walk.npz"), "-o", str(usd), *args]
    )
    assert result.exit_code == 0, result.output
    motion = load_amass(tmp_path / "walk.npz", body_model)
    back, info = read_smpl_motion(usd, body_model)
    assert info.time_codes_per_second == 60.0 and back.num_frames == 20
    err = (Rotation.from_rotvec(back.pose.reshape(-1, 3)).inv() *
           Rotation.from_rotvec(motion.pose.reshape(-1, 3))).magnitude().max()  # fmt: skip
    assert err < 1e-5
    np.testing.assert_allclose(back.trans, motion.trans, atol=1e-5)
    out = tmp_path / "walk_back.npz"
    result = runner.invoke(main, ["export-amass", str(usd), "-o", str(out), *args])
    assert result.exit_code == 0, result.output
    with np.load(out) as again:
        ra = Rotation.from_rotvec(again["poses"][:, :66].reshape(-1, 3))
        rb = Rotation.from_rotvec(data["poses"][:, :66].reshape(-1, 3))
        assert (ra.inv() * rb).magnitude().max() < 1e-5
        np.testing.assert_allclose(again["trans"], data["trans"], atol=1e-5)
        assert float(again["mocap_framerate"]) == 60.0


def test_library_round_trip_with_resampling(tmp_path: Path, body_model: BodyModel) -> None:
    from usd_garment.usd.body_layer import write_body_layer

    _amass_npz(tmp_path / "walk.npz", frames=21, fps=60.0)
    motion = load_amass(tmp_path / "walk.npz", body_model, fps=30.0)
    assert motion.num_frames == 11 and motion.fps == 30.0
    write_body_layer(tmp_path / "walk.usdc", motion, body_model)
    back, _ = read_smpl_motion(tmp_path / "walk.usdc", body_model)
    err = (Rotation.from_rotvec(back.pose.reshape(-1, 3)).inv() *
           Rotation.from_rotvec(motion.pose.reshape(-1, 3))).magnitude().max()  # fmt: skip
    assert err < 1e-5
    save_amass(tmp_path / "again.npz", back, body_model)
    again = load_amass(tmp_path / "again.npz", body_model)
    np.testing.assert_allclose(again.trans, motion.trans, atol=1e-5)


def test_bad_amass_files(tmp_path: Path, body_model: BodyModel) -> None:
    np.savez(tmp_path / "short.npz", poses=np.zeros((3, 30)), trans=np.zeros((3, 3)))
    with pytest.raises(AmassError, match=r"'poses' must be \(T, >=66\)"):
        load_amass(tmp_path / "short.npz", body_model)
    np.savez(tmp_path / "norate.npz", poses=np.zeros((3, 156)), trans=np.zeros((3, 3)))
    with pytest.raises(AmassError, match="mocap_framerate"):
        load_amass(tmp_path / "norate.npz", body_model)
    (tmp_path / "junk.npz").write_bytes(b"junk")
    with pytest.raises(AmassError, match="not a readable"):
        load_amass(tmp_path / "junk.npz", body_model)
    result = CliRunner().invoke(
        main, ["import-amass", str(tmp_path / "junk.npz"), "-o", str(tmp_path / "x.usda")]
    )
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert not (tmp_path / "x.usda").exists()


def test_import_refuses_betas_beyond_the_shape_space(tmp_path: Path) -> None:
    """An AMASS file whose betas the reader would refuse gives one error line and no layer."""
    data = _amass_npz(tmp_path / "a.npz", frames=3)
    data["betas"][4] = 12.0
    np.savez(tmp_path / "a.npz", **data)
    out = tmp_path / "a.usda"
    result = CliRunner().invoke(main, ["import-amass", str(tmp_path / "a.npz"), "-o", str(out)])
    assert result.exit_code == 1 and not out.exists()
    assert result.stderr.strip() == (
        f"Error: {out}: betas[4] = 12 is outside the body's shape space (|beta| <= 5)"
    )


def test_heldout_walk_script(tmp_path: Path) -> None:
    """``examples/heldout_walk.sh`` writes the chart runs' AMASS-style walk: 480 frames at 120 fps
    on its four betas, through a Z-up ``.npz``, reading back as the motion it was exported from."""
    script = Path(__file__).parents[1] / "examples" / "heldout_walk.sh"
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    subprocess.run(
        ["bash", str(script), str(tmp_path)], check=True, capture_output=True,
        env={**os.environ, "PATH": path},
    )  # fmt: skip
    body = load_body_model()
    walk, _ = read_smpl_motion(tmp_path / "amass_walk120.usdc", body)
    source, _ = read_smpl_motion(tmp_path / "amass_walk120_source.usda", body)
    assert walk.pose.shape == (480, 24, 3) and walk.fps == 120.0
    np.testing.assert_allclose(walk.betas[:4], [-0.793, 0.241, -1.896, 1.396], atol=1e-6)
    np.testing.assert_allclose(walk.trans, source.trans, atol=1e-5)
    rotations = Rotation.from_rotvec(walk.pose.reshape(-1, 3)).as_matrix()
    expected = Rotation.from_rotvec(source.pose.reshape(-1, 3)).as_matrix()
    np.testing.assert_allclose(rotations, expected, atol=1e-5)
    npz = np.load(tmp_path / "amass_walk120.npz")
    assert float(npz["mocap_framerate"]) == 120.0
    # Z-up: the npz's root orientation is the Y-up body's turned by the frame change
    root = Rotation.from_rotvec(npz["poses"][:, :3]).as_matrix()
    source_root = expected.reshape(480, 24, 3, 3)[:, 0]
    np.testing.assert_allclose(root, ZUP_TO_YUP.T @ source_root, atol=1e-5)
