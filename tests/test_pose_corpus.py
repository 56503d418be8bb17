"""Pose corpora: the poses of a BVH capture, an AMASS .npz and a USD body layer gathered by
``usd-garment motion poses``, read back, refused when broken, and trained on by ``train pose``
beside the training set's poses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tests.test_learned import TINY, tiny_canonical_set
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.motion.motion_file import read_motion_file
from usd_garment.motion.pose_corpus import build_pose_corpus, load_pose_corpus
from usd_garment.motion.procedural import make_motion
from usd_garment.motion.resample import resample_motion
from usd_garment.training.pipeline import load_stage
from usd_garment.training.pose import evaluate_pose_codec
from usd_garment.usd.body_layer import write_body_layer

CMU_CLIP = Path("/work/shared/mocap/cmu_131_01.bvh")


def amass_npz(path: Path, frames: int = 24, fps: float = 60.0) -> Path:
    """An AMASS-style motion (Z-up, SMPL-H layout): the spine and arms swaying."""
    t = np.arange(frames) / fps
    poses = np.zeros((frames, 156))
    poses[:, :3] = [np.pi / 2, 0.0, 0.0]
    poses[:, 3:66] = 0.2 * np.sin(2.0 * np.pi * t[:, None] + np.arange(63) / 10.0)
    trans = np.stack([np.zeros(frames), t, np.full(frames, 0.9)], axis=1)
    np.savez(path, poses=poses, trans=trans, betas=np.zeros(16), mocap_framerate=fps)
    return path


def test_corpus_of_a_capture_an_amass_motion_and_a_body_layer(
    body_model: BodyModel, tmp_path: Path
) -> None:
    layer = tmp_path / "squat.usda"
    write_body_layer(layer, make_motion("squat", 30, 30.0, seed=2, body=body_model), body_model)
    sources = [CMU_CLIP, amass_npz(tmp_path / "sway.npz"), layer]
    out = tmp_path / "corpus.npz"
    result = CliRunner().invoke(main, ["motion", "poses", *map(str, sources), "-o", str(out)])
    assert result.exit_code == 0, result.output
    corpus = load_pose_corpus(out)
    assert corpus.sources == ["cmu_131_01.bvh", "sway.npz", "squat.usda"] and corpus.fps == 10.0
    assert sum(corpus.counts) == len(corpus.poses) and corpus.counts[1:] == [4, 10]
    assert f"wrote {out}: {len(corpus.poses)} poses of 3 motions at 10 fps" in result.output
    start = 0
    for path, count in zip(sources, corpus.counts, strict=True):
        # the arms as captured: no shoulder opening unless asked
        expected = resample_motion(read_motion_file(path, body_model, arm_clearance=None), 10.0)
        np.testing.assert_allclose(corpus.poses[start : start + count], expected.pose, atol=1e-6)
        start += count


def test_bad_corpus_input(body_model: BodyModel, tmp_path: Path) -> None:
    out = tmp_path / "corpus.npz"
    result = CliRunner().invoke(main, ["motion", "poses", str(tmp_path / "no.bvh"), "-o", str(out)])
    assert result.exit_code == 1 and "no.bvh: no such file" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()
    broken = tmp_path / "broken.bvh"
    broken.write_text("HIERARCHY\nROOT Hips\n{\n")
    result = CliRunner().invoke(main, ["motion", "poses", str(broken), "-o", str(out)])
    assert result.exit_code == 1 and "broken.bvh" in result.output and not out.exists()
    result = CliRunner().invoke(main, ["motion", "poses", str(CMU_CLIP), "-o", str(tmp_path / "c")])
    assert result.exit_code == 2 and "must end in .npz" in result.output
    np.savez(tmp_path / "other.npz", poses=np.zeros((2, 24, 3)))
    with pytest.raises(ValueError, match="not a pose corpus"):
        load_pose_corpus(tmp_path / "other.npz")
    np.savez(tmp_path / "partial.npz", format=np.array(1), poses=np.zeros((2, 24, 3)))
    with pytest.raises(ValueError, match="not a pose corpus"):  # no counts, sources, fps
        load_pose_corpus(tmp_path / "partial.npz")
    with pytest.raises(ValueError, match="no such pose corpus"):
        load_pose_corpus(tmp_path / "missing.npz")


def test_pose_codec_trains_on_the_corpus_too(
    body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path
) -> None:
    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    data, corpus = tmp_path / "set.npz", tmp_path / "corpus.npz"
    tiny_canonical_set(body_model, data)  # 20 training frames
    result = CliRunner().invoke(main, ["motion", "poses", str(amass_npz(tmp_path / "a.npz", 60)),
                                       "-o", str(corpus)])  # fmt: skip
    assert result.exit_code == 0, result.output
    config = tmp_path / "pose.json"
    config.write_text(json.dumps({"pose": {**TINY["pose"], "corpus": str(corpus)}}))
    model = tmp_path / "model"
    result = CliRunner().invoke(main, ["train", "pose", "--data", str(data), "--out", str(model),
                                       "--config", str(config)])  # fmt: skip
    assert result.exit_code == 0, result.output
    history = json.loads((model / "pose.json").read_text())["history"]
    assert history["corpus_poses"] == 10 and history["config"]["corpus"] == str(corpus)
    assert history["train_poses"] + history["validation_poses"] == 20 + 10

    # train pose-error: the run folder's pose code on each motion and on all, as evaluated
    sway, still = amass_npz(tmp_path / "a.npz", 60), amass_npz(tmp_path / "b.npz", 12, 30.0)
    result = CliRunner().invoke(main, ["train", "pose-error", str(model), str(sway), str(still)])
    assert result.exit_code == 0, result.output
    codec = load_stage(model, "pose")[0]
    each = [evaluate_pose_codec(codec, build_pose_corpus([path], body_model).poses)["angle_deg"]
            for path in (sway, still)]  # fmt: skip
    rows = {line.split(" (")[0]: float(line.split()[-1]) for line in result.output.splitlines()
            if "poses)" in line}  # fmt: skip
    assert rows["a.npz"] == pytest.approx(each[0], abs=0.006)
    assert rows["b.npz"] == pytest.approx(each[1], abs=0.006)
    assert rows["all"] == pytest.approx((10 * each[0] + 4 * each[1]) / 14, abs=0.006)
    assert "1 pose code(s), 10-d" in result.output
    result = CliRunner().invoke(main, ["train", "pose-error", str(tmp_path), str(sway)])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1
    result = CliRunner().invoke(main, ["train", "pose-error", str(model), str(tmp_path / "x.bvh")])
    assert result.exit_code == 1 and "x.bvh: no such file" in result.output
    config.write_text(json.dumps({"pose": {**TINY["pose"], "corpus": str(tmp_path / "no.npz")}}))
    result = CliRunner().invoke(main, ["train", "pose", "--data", str(data), "--out",
                                       str(tmp_path / "m2"), "--config", str(config)])  # fmt: skip
    assert result.exit_code == 1 and "no.npz: no such pose corpus file" in result.output
