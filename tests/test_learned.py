"""The learned method end to end on a tiny run: ``train all`` on a small canonical set writes a
model directory (weights, config, log, curves), ``dress --method learned --model`` reads it and
writes the input's time codes, and a model is refused on another body or another template."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from scipy.ndimage import gaussian_filter1d

from tests.script_calls import script_calls
from usd_garment.body.fingerprint import model_fingerprint
from usd_garment.body.model import BodyModel
from usd_garment.canonical.dataset import CanonicalSet, save_canonical_set
from usd_garment.cli.main import main
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.methods.learned import Tangent, _tangents, to_frames
from usd_garment.methods.learned_model import ModelError, load_learned_model
from usd_garment.motion.procedural import make_motion
from usd_garment.training.pose import PoseCodecTrainConfig
from usd_garment.training.regressor import RegressorTrainConfig
from usd_garment.training.vae import VaeTrainConfig
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.garment_read import read_garment_layer

pytest.importorskip("matplotlib")

#: Small networks so that training takes seconds.
TINY = {
    "pose": {"hidden": 32, "epochs": 2, "batch_size": 64},
    "vae": {"epochs": 2, "batch_size": 16, "encoder_hidden": [32], "self_supervised_batch": 8,
            "eval_random": 16, "decoder": {"kind": "basis", "hidden": [32], "basis_size": 8}},
    "regressor": {"hidden": [16], "epochs": 2, "crop_length": 12, "batch_size": 4},
}  # fmt: skip


def tiny_canonical_set(body: BodyModel, path: Path, flagged: np.ndarray | None = None) -> None:
    """Three short sequences (train, validation, test) of the low T-shirt, breathing in and out
    with the motion: enough for the pipeline, not a garment model. ``flagged``: ``(60,)`` bool,
    the frames the simulation flagged (no record if None)."""
    template = load_template("tshirt", "low")
    v = template.vertices.astype(np.float32)
    canonical, pose, trans, offsets = [], [], [], [0]
    for seed in range(3):
        motion = make_motion("walk", 20, 30.0, seed=seed, body=body)
        swell = 0.003 * np.sin(np.linspace(0, 3, 20, dtype=np.float32))[:, None, None]
        canonical.append(v[None] * (1.0 + swell))
        pose.append(motion.pose)
        trans.append(motion.trans)
        offsets.append(offsets[-1] + 20)
    frames = sum(len(c) for c in canonical)
    save_canonical_set(
        path,
        CanonicalSet(
            canonical=np.concatenate(canonical), frame_offsets=np.array(offsets),
            betas=np.zeros((3, 10)), pose=np.concatenate(pose), trans=np.concatenate(trans),
            fps=np.full(3, 30.0), error=np.zeros(frames), max_error=np.zeros(frames),
            template=v, faces=template.faces, sources=["a", "b", "c"],
            splits=["train", "validation", "test"], metadata={"garment": "tshirt", "lod": "low"},
            flagged=flagged,
        ),
    )  # fmt: skip


def _run(args: list[object]) -> tuple[int, str]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(result.exception, AssertionError)
    return result.exit_code, result.output


def test_train_then_dress(body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path) -> None:
    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    data, model = tmp_path / "set.npz", tmp_path / "model"
    tiny_canonical_set(body_model, data)
    config = tmp_path / "tiny.json"
    config.write_text(json.dumps(TINY))
    code, output = _run(["train", "all", "--data", data, "--out", model, "--config", config])
    assert code == 0, output
    for name in ("model.json", "weights.safetensors", "curves.png", "train.log", "config.json"):
        assert (model / name).is_file(), name
    log = (model / "train.log").read_text().splitlines()
    assert [line.split()[2] for line in log] == ["pose"] * 2 + ["vae"] * 2 + ["regressor"] * 2
    info = json.loads((model / "model.json").read_text())
    assert info["garment"] == "tshirt" and info["vertices"] == 1015 and info["lod"] == "low"
    assert info["body"]["fingerprint"] == model_fingerprint(body_model)
    assert info["command"].startswith("usd-garment train all")
    assert load_learned_model(model, body_model).members[0].vae.num_vertices == 1015

    # a resume that finds every stage done keeps the time its epochs took
    code, output = _run(["train", "all", "--data", data, "--out", model, "--config", config,
                         "--resume"])  # fmt: skip
    assert code == 0, output
    seconds = json.loads((model / "model.json").read_text())["training"]["seconds"]
    for stage in ("pose", "vae", "regressor"):
        record = json.loads((model / f"{stage}.json").read_text())
        assert record["resumed_epochs"] == 2 and seconds[stage] == record["seconds"]
        assert record["seconds"] >= sum(row["seconds"] for row in record["history"]["epochs"])
    command = json.loads((model / "model.json").read_text())["command"]
    code, output = _run(["train", "regressor", "--data", data, "--out", model, "--config", config,
                         "--resume"])  # fmt: skip
    assert code == 0, output  # it trained nothing: the record names no second command
    assert json.loads((model / "model.json").read_text())["command"] == command

    body = tmp_path / "walk.usda"  # 60 fps, so the networks' 30 fps is resampled both ways
    write_body_layer(body, make_motion("walk", 9, 60.0, seed=5, body=body_model), body_model)
    out = tmp_path / "walk_tshirt.usdc"
    code, output = _run(["dress", body, "-o", out, "--model", model, "--lod", "low"])
    assert code == 0, output
    points, _, layer = read_garment_layer(out)
    assert points.shape == (9, 1015, 3) and np.isfinite(points).all()
    assert layer.method == "learned+preimage"  # a model directory gets the default's method
    np.testing.assert_array_equal(layer.time_codes, np.arange(9))

    code, output = _run(["dress", body, "-o", tmp_path / "x.usdc", "--model", model])
    assert code == 1 and "1015 vertices" in output  # trained on the low T-shirt, not the high
    with pytest.raises(ModelError, match="trained for the body"):
        load_learned_model(model, synthetic_body)
    code, output = _run(["dress", body, "-o", tmp_path / "y.usdc", "--model", tmp_path])
    assert code == 1 and "not a model directory" in output
    assert not (tmp_path / "x.usdc").exists() and not (tmp_path / "y.usdc").exists()

    code, output = _run(["train", "compare", model, "-o", tmp_path / "fig4.png"])
    assert code == 0 and (tmp_path / "fig4.png").is_file()

    # fine-tuning in a copy: from the trained regressor, with the posed collision term, the
    # decoder moving too (its VAE stage is written again)
    tuned = tmp_path / "tuned"
    shutil.copytree(model, tuned)
    regressor = {**TINY["regressor"], "epochs": 1, "lambda_posed": 1.0, "tune_decoder": True}
    config.write_text(json.dumps({**TINY, "regressor": regressor}))
    planes = tmp_path / "planes.npz"
    code, output = _run(["train", "regressor", "--data", data, "--out", tuned, "--config", config,
                         "--seed", 4, "--init-from", model, "--planes", planes])  # fmt: skip
    assert code == 0, output
    assert planes.is_file()
    # the record names every command that made the folder's networks, the options included
    command = json.loads((tuned / "model.json").read_text())["command"]
    first = json.loads((model / "model.json").read_text())["command"]
    assert command.startswith(f"{first}; then usd-garment train regressor --data {data}")
    assert command.endswith(f"--out {tuned} --device cpu --config {config} --seed 4 "
                            f"--init-from {model} --planes {planes}")  # fmt: skip
    settings = json.loads((tuned / "config.json").read_text())
    assert [settings[stage]["seed"] for stage in ("pose", "vae", "regressor")] == [4, 4, 4]
    row = json.loads((tuned / "regressor.json").read_text())["history"]["epochs"][-1]
    assert row["train_posed"] >= 0 and row["train_vertex_mm"] > 0 and "val_posed_inside_pct" in row
    vae_record = json.loads((tuned / "vae.json").read_text())
    assert vae_record["tuned_with_regressor"]["init_from"] == str(model)
    old, new = (load_learned_model(m, body_model).members[0].vae.decoder for m in (model, tuned))
    pairs = zip(old.parameters(), new.parameters(), strict=True)
    assert any(not torch.equal(a, b) for a, b in pairs)  # the decoder moved

    # a NaN setting is refused before anything is trained or written
    before = (tuned / "regressor.json").read_text()
    nan = {**TINY, "regressor": {**regressor, "lambda_posed": float("nan")}}
    config.write_text(json.dumps(nan))
    code, output = _run(["train", "regressor", "--data", data, "--out", tuned, "--config", config])
    assert code == 1 and "lambda_posed must be a finite number, got nan" in output
    assert (tuned / "regressor.json").read_text() == before


@pytest.mark.parametrize(
    ("make", "name"),
    [(RegressorTrainConfig, "lr"), (RegressorTrainConfig, "lambda_vertex"),
     (RegressorTrainConfig, "grad_clip"), (VaeTrainConfig, "lambda_kl"),
     (PoseCodecTrainConfig, "lr_decay")],
)  # fmt: skip
def test_training_configs_refuse_settings_that_are_not_finite(make: type, name: str) -> None:
    for value in (float("nan"), float("inf"), -float("inf")):
        with pytest.raises(ValueError, match=f"^{name} must be a finite number"):
            make(**{name: value})
    make(**{name: 0.5})  # a finite value is taken


def _log_figures(model: Path) -> list[dict[str, float]]:
    """The figures of each line of the run's ``train.log`` (times and learning rates left out)."""
    rows = []
    for line in (model / "train.log").read_text().splitlines():
        pairs = (word.split("=") for word in line.split()[4:])
        rows.append({k: float(v) for k, v in pairs if k not in ("seconds", "lr")})
    return rows


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_training_on_cuda_is_the_training_on_the_cpu(
    body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path
) -> None:
    """``train all --device cuda`` trains what the CPU trains (every logged figure of every
    epoch within 2 %, shares of vertices within 0.05 points), and its model directory loads and
    dresses on the CPU."""
    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    data, config = tmp_path / "set.npz", tmp_path / "tiny.json"
    tiny_canonical_set(body_model, data)
    config.write_text(json.dumps(TINY))
    figures = {}
    for device in ("cpu", "cuda"):
        model = tmp_path / device
        code, output = _run(["train", "all", "--data", data, "--out", model, "--config", config,
                             "--device", device])  # fmt: skip
        assert code == 0, output
        figures[device] = _log_figures(model)
        assert json.loads((model / "model.json").read_text())["command"].endswith(
            f"--device {device} --config {config}"
        )
    assert len(figures["cuda"]) == len(figures["cpu"]) == 6
    _assert_same_figures(figures["cpu"], figures["cuda"])
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 5, 30.0, seed=5, body=body_model), body_model)
    points = {}
    for device in ("cpu", "cuda"):
        out = tmp_path / f"{device}.usdc"
        code, output = _run(["dress", body, "-o", out, "--model", tmp_path / device,
                             "--lod", "low"])  # fmt: skip
        assert code == 0, output
        points[device] = read_garment_layer(out)[0]
    np.testing.assert_allclose(points["cuda"], points["cpu"], atol=2e-3)


def _assert_same_figures(cpu: list[dict[str, float]], cuda: list[dict[str, float]]) -> None:
    """Each logged figure within 2 % (shares of vertices within 0.05 points)."""
    for cpu_row, cuda_row in zip(cpu, cuda, strict=True):
        assert cpu_row.keys() == cuda_row.keys()
        for key in cpu_row:
            atol = 0.05 if key.endswith("_pct") else 1e-6
            assert cuda_row[key] == pytest.approx(cpu_row[key], rel=0.02, abs=atol), key


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_fine_tuning_on_cuda_is_the_fine_tuning_on_the_cpu(
    body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path
) -> None:
    """The end-to-end fine-tune (the posed collision term on the CPU's planes, the decoder
    moving, the frames the simulation flagged skipped) of one CPU-trained model, run with
    ``--device cuda``, logs what the CPU's logs."""
    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    data, config, model = tmp_path / "set.npz", tmp_path / "tiny.json", tmp_path / "model"
    tiny_canonical_set(body_model, data, flagged=np.isin(np.arange(60), [4, 5, 6, 15]))
    config.write_text(json.dumps(TINY))
    code, output = _run(["train", "all", "--data", data, "--out", model, "--config", config])
    assert code == 0, output
    regressor = {**TINY["regressor"], "init_from": str(model), "lambda_posed": 1.0,
                 "tune_decoder": True, "skip_flagged_frames": True}  # fmt: skip
    config.write_text(json.dumps({**TINY, "regressor": regressor}))
    figures = {}
    for device in ("cpu", "cuda"):
        tuned = tmp_path / device
        shutil.copytree(model, tuned)
        code, output = _run(["train", "regressor", "--data", data, "--out", tuned, "--config",
                             config, "--device", device])  # fmt: skip
        assert code == 0, output
        figures[device] = _log_figures(tuned)  # the copied run's lines, then the fine-tune's
        assert "val_posed_inside_pct" in figures[device][-1]
    _assert_same_figures(figures["cpu"], figures["cuda"])


def test_latents_return_to_the_input_frames() -> None:
    values = torch.arange(4, dtype=torch.float32)[:, None]  # at 30 fps: t = 0, 1/30, 2/30, 3/30
    at_60 = to_frames(values, 60.0, 7)
    np.testing.assert_allclose(at_60[:, 0].numpy(), [0, 0.5, 1, 1.5, 2, 2.5, 3])
    at_15 = to_frames(values, 15.0, 2)
    np.testing.assert_allclose(at_15[:, 0].numpy(), [0, 2])
    np.testing.assert_allclose(to_frames(values[:1], 24.0, 3)[:, 0].numpy(), [0, 0, 0])


def test_latents_return_to_the_input_frames_on_their_side_of_a_cut() -> None:
    """A cut at frame 6 of a motion at 120 fps (0.05 s) falls at the model's frame 2 (1/15 s):
    the input frames 4 and 5, before the cut, take the model's frame 1, and 6 and 7 its frame
    2, where without the cut they blend the two sides."""
    values = torch.arange(5, dtype=torch.float32)[:, None]  # at 30 fps
    blended = [0, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 1.75, 2, 2.25]
    np.testing.assert_allclose(to_frames(values, 120.0, 10)[:, 0].numpy(), blended)
    cut = to_frames(values, 120.0, 10, cuts=(6,))
    np.testing.assert_allclose(cut[:, 0].numpy(), [0, 0.25, 0.5, 0.75, 1, 1, 2, 2, 2, 2.25])
    np.testing.assert_allclose(to_frames(values, 30.0, 5, cuts=(2,))[:, 0].numpy(), range(5))


def test_the_fields_tangent_is_kept_across_chunks_while_it_is_the_cheaper() -> None:
    fields = load_body_fields()
    x = torch.as_tensor(load_template("tshirt", "low").vertices).expand(8, -1, -1)
    n = x.shape[1]
    (first,) = _tangents(fields, x, None)
    assert first.frames == slice(0, 8) and first.far_per_frame == 0.0
    assert first.tangent is not None and torch.allclose(first.tangent.anchor, x[0])
    assert _tangents(fields, x + 0.005, first)[0].tangent is first.tangent  # 5 mm off
    moved = x.clone()
    moved[:, : n // 2] += 0.05  # half of each frame beyond the radius: 4 N exact lookups
    assert _tangents(fields, moved, first)[0].tangent is first.tangent  # fewer than 7 N
    moved[:, n // 2 :] += 0.05  # all of it: 8 N
    (again,) = _tangents(fields, moved, first)
    assert again.far_per_frame == 0.0 and again.tangent is not None
    assert torch.allclose(again.tangent.anchor, moved.mean(dim=0))


def test_a_chunk_whose_garment_moves_far_gets_an_anchor_per_part() -> None:
    fields = load_body_fields()
    x = torch.as_tensor(load_template("tshirt", "low").vertices).expand(32, -1, -1).clone()
    x[16:] += 0.05  # the second half 5 cm away: about the whole mean, every point is far
    second = x[16:].clone()
    parts = _tangents(fields, x, None)
    assert [p.frames for p in parts] == [slice(0, 16), slice(16, 32)]
    for part in parts:
        assert part.far_per_frame == 0.0 and part.tangent is not None
        assert torch.allclose(part.tangent.anchor, x[part.frames].mean(dim=0))
    x[16:] -= 0.045  # 5 mm: within the radius, one anchor is the cheaper
    assert [p.frames for p in _tangents(fields, x, None)] == [slice(0, 32)]
    # the previous chunk's last part is kept for the whole next chunk while it is the cheaper
    kept = _tangents(fields, second + 0.001, Tangent(slice(16, 32), parts[1].tangent, 0.0))
    assert len(kept) == 1 and kept[0].frames == slice(0, 16)
    assert kept[0].tangent is parts[1].tangent


def test_the_fields_tangent_matches_central_differences() -> None:
    fields = load_body_fields()
    anchor = torch.as_tensor(load_template("tshirt", "low").vertices[:50])
    tangent = fields.linearized(anchor, step=2e-3)
    value = torch.cat(fields._fields(anchor, fields._all_names), dim=-1)
    np.testing.assert_array_equal(tangent.value.numpy(), value.numpy())  # one lookup of 7 N
    for axis in range(3):
        offset = torch.zeros(3)
        offset[axis] = 2e-3
        plus = torch.cat(fields._fields(anchor + offset, fields._all_names), dim=-1)
        minus = torch.cat(fields._fields(anchor - offset, fields._all_names), dim=-1)
        difference = ((plus - minus) / 4e-3).numpy()
        np.testing.assert_allclose(tangent.derivative[..., axis].numpy(), difference, atol=1e-5)


@pytest.mark.parametrize(("garment", "vertices"), [("tshirt", 4405), ("dress", 4432)])
def test_shipped_model_is_the_default(
    garment: str, vertices: int, body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path
) -> None:
    from usd_garment.dress import dress
    from usd_garment.methods.learned import SHIPPED_MODELS, default_method, shipped_model

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    folder = shipped_model(garment, "high")
    assert folder == SHIPPED_MODELS / garment
    assert default_method(garment, "high") == "learned+preimage"
    assert default_method(garment, "low", "draft") == "learned"
    assert default_method(garment, "high", "final") == "learned+postprocess"
    with pytest.raises(ValueError, match="unknown quality 'best'"):
        default_method(garment, "high", "best")
    assert sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) <= 12 * 2**20
    model = load_learned_model(folder, body_model)
    assert model.vertices == vertices
    # One member trained by 'train all', or an ensemble of such members ('train combine').
    trained = [member.info for member in model.members if member.info] or [model.info]
    assert len(trained) == len(model.members)
    for info in trained:
        assert info["command"].startswith("usd-garment train all") and info["ablation"] == "none"
        assert set(info["training"]["data"]["frames"]) == {"train", "validation", "test"}
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 12, 30.0, seed=21, body=body_model), body_model)
    out = tmp_path / f"walk_{garment}.usdc"
    code, output = _run(["dress", body, "-o", out, "--garment", garment])
    assert code == 0, output
    points, _, layer = read_garment_layer(out)
    assert layer.method == "learned+preimage" and points.shape == (12, vertices, 3)
    assert np.isfinite(points).all()
    result = dress(body, tmp_path / "library.usdc", garment=garment)  # no method: the same
    assert result.method == "learned+preimage"
    np.testing.assert_array_equal(read_garment_layer(tmp_path / "library.usdc")[0], points)


def _run_folder_named(settings: dict[str, Any]) -> dict[str, Any]:
    """``settings`` with the regressor's ``init_from`` cut to the run folder's name: the recipe's
    RUNS puts the folders anywhere (the T-shirt's version 8: ``RUNS=scratch/runs_rest``) and names
    them with ``--init-from``."""
    regressor = dict(settings["regressor"])
    if regressor.get("init_from"):
        regressor["init_from"] = Path(regressor["init_from"]).name
    return {**settings, "regressor": regressor}


#: How many members each shipped model has: the recipe's three (``examples/train/recipe.sh``),
#: and for the T-shirt (version 10) two more of ``examples/train/capture_members.sh``.
SHIPPED_MEMBERS = {"tshirt": 5, "dress": 3}


@pytest.mark.parametrize("garment", ["tshirt", "dress"])
def test_the_shipped_members_were_trained_with_the_committed_settings(garment: str) -> None:
    """Each member of a shipped ensemble records the settings of the last file in
    ``examples/train/`` that its command names, the last step's (seed, GRU width, VAE epochs,
    the dress's pose code weighted by the garment, a fine-tuning; defaults elsewhere), with that
    step's ``--seed`` and ``--init-from`` over them as ``train`` applies them."""
    from usd_garment.cli.train import _settings
    from usd_garment.methods.learned import shipped_model
    from usd_garment.training.pipeline import TrainSettings

    folder = shipped_model(garment)
    assert folder is not None
    root = Path(__file__).parent.parent
    members = load_learned_model(folder).members
    assert len(members) == SHIPPED_MEMBERS[garment]
    named = set()
    for member in members:
        found = re.findall(r"--config (examples/train/\S+\.json)", member.info["command"])
        assert found, member.info["command"]
        named.add(found[-1])
        last = member.info["command"].split("; then ")[-1]
        seed = re.findall(r"--seed (\d+)", last)
        init_from = re.findall(r"--init-from (\S+)", last)
        settings = _settings(
            folder, root / found[-1], None, (), "cpu",
            int(seed[-1]) if seed else None, Path(init_from[-1]) if init_from else None,
        )  # fmt: skip
        # Read back through TrainSettings: records older than a setting get its default.
        recorded = TrainSettings.from_dict(member.info["training"]["settings"])
        assert _run_folder_named(recorded.to_dict()) == _run_folder_named(settings.to_dict()), (
            found[-1]
        )
    assert len(named) == 3  # one file per member


@pytest.mark.parametrize("garment", ["tshirt", "dress"])
def test_the_recipe_script_trains_the_shipped_members_steps(garment: str, tmp_path: Path) -> None:
    """``examples/train/recipe.sh GARMENT`` trains each member's pose code and VAE with
    settings equal to what the shipped member records for those stages (its first regressor on
    30-frame crops with the member's seed, no fine-tuning), then each regressor step from a copy
    of the step before (the folder that the step's settings start from), the last with the file
    that the shipped member's command names; then joins the three members with the shipped
    model's latent and posed smoothing."""
    from usd_garment.methods.learned import shipped_model
    from usd_garment.training.pipeline import TrainSettings

    folder = shipped_model(garment)
    assert folder is not None
    model = load_learned_model(folder)
    calls = script_calls("recipe.sh", garment, "MODEL", tmp_path=tmp_path)
    work = tmp_path / "work"

    def settings(path: str) -> TrainSettings:
        loaded = TrainSettings.from_dict(json.loads((work / path).read_text()))
        loaded.set_device("cpu")
        return loaded

    last_steps = []
    recipe_members = model.members[:3]  # the others are capture_members.sh's (test_ensemble)
    for m, member in enumerate(recipe_members):
        recorded = TrainSettings.from_dict(member.info["training"]["settings"]).to_dict()
        first = calls.pop(0)
        assert first[:2] == ["train", "all"] and first[first.index("--config") + 1].endswith(
            f"{m}.json"
        )
        step1 = settings(first[first.index("--config") + 1])
        assert step1.to_dict()["pose"] == recorded["pose"]
        assert step1.to_dict()["vae"] == recorded["vae"]
        assert (step1.regressor.crop_length, step1.regressor.seed) == (30, m)
        assert step1.regressor.init_from is None and step1.regressor.lambda_posed == 0
        before = first[first.index("--out") + 1]
        while calls[0][:2] == ["train", "regressor"]:
            step = calls.pop(0)
            out = step[step.index("--out") + 1]
            if "--config" in step:
                config = step[step.index("--config") + 1]
                step_settings = settings(config).regressor
                # a fine-tuning starts from the step before (the settings name it too, for
                # scratch/runs); the others train from nothing
                fine_tuning = step_settings.lambda_posed > 0
                assert step_settings.init_from == (before if fine_tuning else None), config
                assert ("--init-from" in step) == fine_tuning
                if fine_tuning:
                    assert step[step.index("--init-from") + 1] == before
                assert step_settings.seed == m and "--seed" not in step
            before = out
        last_steps.append(before)
        assert f"--config {config}" in member.info["command"]
    (combine,) = calls
    assert combine[:2] == ["train", "combine"] and combine[2:5] == last_steps
    smoothing = float(combine[combine.index("--latent-smoothing") + 1])
    assert smoothing == model.latent_smoothing
    assert float(combine[combine.index("--posed-smoothing") + 1]) == model.posed_smoothing


def test_the_recipe_script_trains_again_with_other_seeds(tmp_path: Path) -> None:
    """``SEEDS="3 4 5" RUNS=FOLDER recipe.sh``: every command of member m gets ``--seed``
    3 + m, the run folders are in FOLDER, and each fine-tuning starts from the folder of the
    step before there (not the one its settings name); SEEDS with another count is refused."""
    env = {"SEEDS": "3 4 5", "RUNS": "scratch/again"}
    calls = script_calls("recipe.sh", "dress", "MODEL", tmp_path=tmp_path, env=env)
    trains = [c for c in calls if c[1] in ("all", "regressor")]
    assert len(trains) == 9
    for k, call in enumerate(trains):
        m = k // 3
        assert call[call.index("--seed") + 1] == str(3 + m)
        assert call[call.index("--out") + 1].startswith("scratch/again/dress_")
        if "--init-from" in call:
            before = trains[k - 1]
            assert call[call.index("--init-from") + 1] == before[before.index("--out") + 1]
    assert sum("--init-from" in c for c in trains) == 3
    (tmp_path / "two").mkdir()
    with pytest.raises(subprocess.CalledProcessError):
        script_calls("recipe.sh", "dress", "M", tmp_path=tmp_path / "two", env={"SEEDS": "3 4"})


def test_the_recipe_script_trains_the_first_steps_at_once(tmp_path: Path) -> None:
    """``AT_ONCE=1 recipe.sh``: the three members' ``train all`` first (run at once, so in any
    order), each once, then the same regressor steps and join as one member after another."""
    for name in ("one", "at_once"):
        (tmp_path / name).mkdir()
    one_by_one = script_calls("recipe.sh", "tshirt", "MODEL", tmp_path=tmp_path / "one")
    at_once = script_calls(
        "recipe.sh", "tshirt", "MODEL", tmp_path=tmp_path / "at_once", env={"AT_ONCE": "1"}
    )
    firsts = [c for c in one_by_one if c[:2] == ["train", "all"]]
    assert len(firsts) == 3
    assert sorted(at_once[:3]) == sorted(firsts)
    assert at_once[3:] == [c for c in one_by_one if c[:2] != ["train", "all"]]


def test_the_recipe_script_trains_only_the_members_named(tmp_path: Path) -> None:
    """``MEMBERS="0" TRAIN_ARGS="--ablation no-collision" recipe.sh``: member 0's steps alone,
    the ablation on each of them, and no join (a model needs all three members); the same
    commands as member 0's in a whole run."""
    for name in ("whole", "one"):
        (tmp_path / name).mkdir()
    env = {"TRAIN_ARGS": "--ablation no-collision"}
    whole = script_calls("recipe.sh", "tshirt", "MODEL", tmp_path=tmp_path / "whole", env=env)
    one = script_calls("recipe.sh", "tshirt", "MODEL", tmp_path=tmp_path / "one",
                       env={**env, "MEMBERS": "0"})  # fmt: skip
    assert one == [c for c in whole if c[c.index("--out") + 1].endswith("_m0")]
    assert len(one) == 4 and all(c[c.index("--ablation") + 1] == "no-collision" for c in one)
    for wrong in ("3", "0 0", "0 x"):  # a member that is not one of the three, or twice
        (tmp_path / "wrong").mkdir()
        with pytest.raises(subprocess.CalledProcessError):
            script_calls("recipe.sh", "tshirt", "M", tmp_path=tmp_path / "wrong",
                         env={"MEMBERS": wrong})  # fmt: skip
        shutil.rmtree(tmp_path / "wrong")


@pytest.mark.parametrize("garment", ["tshirt", "dress"])
def test_the_table1_script_trains_each_ablation_with_the_whole_recipe(
    garment: str, tmp_path: Path
) -> None:
    """``examples/train/table1.sh GARMENT OUT``: for each ablation, every command of the
    recipe (``recipe.sh``'s, and for the T-shirt ``capture_members.sh``'s too, on the recipe's
    members) with that ablation, then ``TRAIN_ARGS``, and in that ablation's run folders; the
    T-shirt's five members joined as the shipped model is; Fig. 4 of member 0's VAEs; then one
    bench of the shipped model (its networks alone and its default method), each ablation,
    ``lbs`` and ``lbs+postprocess`` on the test split and the AMASS-style walk."""
    env = {"TRAIN_ARGS": "--epochs vae=1"}  # a quick try's, after the ablation
    calls = script_calls("table1.sh", garment, "T1", "D", "C", tmp_path=tmp_path, env=env)
    ablations = ("no-collision", "no-self-supervision")
    trains = [c for c in calls if c[:2] in (["train", "all"], ["train", "regressor"])]
    members = 5 if garment == "tshirt" else 3
    per_member = 4 if garment == "tshirt" else 3  # train all, then the regressor's steps
    # the T-shirt's capture members: six regressor steps on member 0's first step, not a base of
    # their own trained again (the same command)
    assert len(trains) == 2 * (3 * per_member + (6 if garment == "tshirt" else 0))
    for ablation in ablations:
        mine = [c for c in trains if c[c.index("--ablation") + 1] == ablation]
        assert len(mine) == len(trains) // 2
        assert all(c[c.index("--out") + 1].startswith(f"T1/runs/{ablation}/") for c in mine)
        assert all(c[c.index("--epochs") + 1] == "vae=1" for c in mine)
    combines = [c for c in calls if c[:2] == ["train", "combine"]]
    finals = [c for c in combines if c[c.index("--out") + 1] in
              [f"T1/{garment}_{a}" for a in ablations]]  # fmt: skip
    assert len(finals) == 2 and all(len(c[2 : c.index("--out")]) == members for c in finals)
    if garment == "tshirt":  # the recipe's three kept as members, beside two capture members
        assert all(c[c.index("--weights") + 1] == "int8" for c in finals)
        kept = [c[2] for c in calls if c[:2] == ["train", "member"]]
        assert kept == ["T1/tshirt_no-collision_recipe"] * 3 + [
            "T1/tshirt_no-self-supervision_recipe"] * 3  # fmt: skip
    firsts = [c[c.index("--out") + 1] for c in trains if c[:2] == ["train", "all"]]
    (compare,) = [c for c in calls if c[:2] == ["train", "compare"]]  # Fig. 4: member 0's VAEs
    assert compare[2:4] == [f for f in firsts if f.endswith("_m0") and "cap_" not in f]
    assert compare[compare.index("-o") + 1] == "T1/fig4.png"
    (bench,) = [c for c in calls if c[0] == "bench"]
    assert bench[1] == "T1/heldout/amass_walk120.usdc"
    value = dict(zip(bench[2::2], bench[3::2], strict=False))
    assert value["--manifest"] == f"D/dataset_{garment}_v4" and value["--split"] == "test"
    assert [bench[i + 1] for i, a in enumerate(bench) if a == "--method"] == [
        "learned", "learned+preimage", "lbs", "lbs+postprocess"]  # fmt: skip
    assert [bench[i + 1] for i, a in enumerate(bench) if a == "--model"] == [
        f"{a}=T1/{garment}_{a}" for a in ablations]  # fmt: skip
    (tmp_path / "wrong").mkdir()
    with pytest.raises(subprocess.CalledProcessError):
        script_calls("table1.sh", "skirt", "T1", tmp_path=tmp_path / "wrong")


def test_a_failed_first_step_at_once_stops_the_other_members(tmp_path: Path) -> None:
    """``AT_ONCE=1 recipe.sh``: when one member's ``train all`` fails, the two still training
    are stopped and the recipe exits with an error, rather than waiting on them."""
    stand_in = tmp_path / "bin" / "usd-garment"
    stand_in.parent.mkdir()
    stand_in.write_text(
        f"#!{sys.executable}\n"
        "import os, pathlib, sys, time\n"
        "out = sys.argv[sys.argv.index('--out') + 1]\n"
        "if out.endswith('_m1'):  # fails once the two others are training\n"
        f"    folder = pathlib.Path({str(tmp_path)!r})\n"
        "    while not all((folder / f'tshirt_T30_m{m}').exists() for m in (0, 2)):\n"
        "        time.sleep(0.05)\n"
        "    sys.exit(1)\n"
        f"mine = pathlib.Path({str(tmp_path)!r}, pathlib.Path(out).name)\n"
        "mine.with_suffix('.tmp').write_text(str(os.getpid()))\n"
        "mine.with_suffix('.tmp').rename(mine)  # whole when it appears\n"
        "time.sleep(120)\n"
    )
    stand_in.chmod(0o755)
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(Path(__file__).parent.parent / "examples")
    env = {
        **os.environ,
        "AT_ONCE": "1",
        "PATH": f"{stand_in.parent}{os.pathsep}{os.environ['PATH']}",
    }
    done = subprocess.run(
        ["bash", "examples/train/recipe.sh", "tshirt", "MODEL"], env=env, cwd=work,
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode != 0 and "a member's first step failed" in done.stderr
    for name in ("tshirt_T30_m0", "tshirt_T30_m2"):
        pid = int((tmp_path / name).read_text())  # it was training: it must be gone now
        for _ in range(50):
            if _state(pid) in ("", "Z"):
                break
            time.sleep(0.1)
        assert _state(pid) in ("", "Z")


def _state(pid: int) -> str:
    """The state letter of process ``pid`` (``/proc/PID/stat``), empty once it is gone."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return ""


def test_final_quality_pushes_the_learned_garment_out(body_model: BodyModel,
                                                      synthetic_body: BodyModel,
                                                      tmp_path: Path) -> None:  # fmt: skip
    """``--quality final`` dresses with learned+postprocess: the shipped model's garment, then
    no vertex left inside the posed body elsewhere than where the pose forces it; with no
    quality, learned+preimage leaves no more inside elsewhere than the networks alone."""
    from usd_garment.eval.evaluate import evaluate_layer

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    body = tmp_path / "run.usda"
    write_body_layer(body, make_motion("run", 10, 30.0, seed=8, body=body_model), body_model)
    shares = {}
    runs = {
        "learned": ["--method", "learned"],
        "learned+preimage": [],
        "learned+postprocess": ["--quality", "final"],
    }
    for method, extra in runs.items():
        out = tmp_path / f"{method}.usdc"
        code, output = _run(["dress", body, "-o", out, *extra])
        assert code == 0, output
        points, _, layer = read_garment_layer(out)
        assert layer.method == method and points.shape == (10, 4405, 3)
        shares[method] = evaluate_layer(out, body)[0].summary()["inside_elsewhere_share"]
    assert shares["learned+postprocess"] == 0.0, shares
    assert shares["learned+preimage"] <= shares["learned"], shares


def test_draft_carries_the_shipped_model_down(body_model: BodyModel, synthetic_body: BodyModel,
                                              tmp_path: Path) -> None:  # fmt: skip
    """``--quality draft`` dresses the low mesh with the high model's networks: its garment is
    the high one carried down through the rest-surface correspondence."""
    from usd_garment.garment.lod import carry_to_lod

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 6, 30.0, seed=4, body=body_model), body_model)
    code, output = _run(["dress", body, "-o", tmp_path / "draft.usdc", "--quality", "draft"])
    assert code == 0, output
    draft, _, layer = read_garment_layer(tmp_path / "draft.usdc")
    assert layer.method == "learned"
    assert draft.shape == (6, len(load_template("tshirt", "low").vertices), 3)
    code, output = _run(["dress", body, "-o", tmp_path / "high.usdc", "--method", "learned"])
    assert code == 0, output
    high = read_garment_layer(tmp_path / "high.usdc")[0]
    np.testing.assert_allclose(draft, carry_to_lod(high, "tshirt", "high", "low"), atol=1e-5)


def test_learned_method_times_its_stages(body_model: BodyModel, synthetic_body: BodyModel,
                                         tmp_path: Path) -> None:  # fmt: skip
    """The per-stage seconds that ``benchmarks/bench_dress.py`` reports in ms per frame."""
    from usd_garment.dress import dress
    from usd_garment.methods.learned import (
        STAGES,
        LearnedCanonicalMethod,
        LearnedMethod,
        LearnedPreimageMethod,
    )

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 6, 30.0, seed=4, body=body_model), body_model)
    method = LearnedMethod()
    dress(body, tmp_path / "g.usdc", method=method, lod="low")
    assert set(method.seconds) == set(STAGES)
    ran = {k for k, v in method.seconds.items() if v > 0}
    assert ran == {"load", "regressor", "decoder", "fields", "posing", "carry"}
    canonical = LearnedCanonicalMethod()
    dress(body, tmp_path / "c.usdc", method=canonical, lod="low")
    ran = {k for k, v in canonical.seconds.items() if v > 0}
    assert ran == {"load", "regressor", "decoder", "canonical", "fields", "posing", "carry"}
    preimage = LearnedPreimageMethod()
    dress(body, tmp_path / "p.usdc", method=preimage, lod="low")
    ran = {k for k, v in preimage.seconds.items() if v > 0}
    assert ran == {
        "load", "regressor", "decoder", "canonical", "fields", "posing", "preimage", "carry",
    }  # fmt: skip


def test_pushing_methods_push_the_vertices_they_write(
    body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """At a coarser level of detail than the model's, ``learned+preimage`` carries the decoded
    canonical garment down before its pushes (a garment pushed at the model's level and carried
    down posed can be inside again between its vertices): both pushes see the low mesh's
    vertices, and the layer has them."""
    import usd_garment.methods.learned as learned
    from usd_garment.dress import dress

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    seen: dict[str, int] = {}

    def spy(name: str, push: Any) -> Any:
        def wrapped(points: torch.Tensor, *args: Any) -> torch.Tensor:
            seen[name] = points.shape[1]
            return push(points, *args)

        return wrapped

    monkeypatch.setattr(learned, "push_out_canonical", spy("canonical", learned.push_out_canonical))
    monkeypatch.setattr(learned, "preimage_push", spy("preimage", learned.preimage_push))
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 4, 30.0, seed=4, body=body_model), body_model)
    dress(body, tmp_path / "p.usdc", method=learned.LearnedPreimageMethod(), lod="low")
    low = len(load_template("tshirt", "low").vertices)
    assert seen == {"canonical": low, "preimage": low}
    assert read_garment_layer(tmp_path / "p.usdc")[0].shape == (4, low, 3)


def test_posing_workers_stream_the_garment_of_one_process(
    body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """``learned+preimage`` with two forked workers (each chunk posed and pushed there while
    this process decodes the next) streams the garment of one process at one thread to the bit
    (the shipped T-shirt's networks, with and without a posed smoothing), in chunks of the size
    asked for, in order, with this process's torch threads as they were; a motion of fewer than
    two chunks a worker is posed in this process."""
    import usd_garment.methods.learned as learned
    from usd_garment.methods.learned_posing import PosingPool, can_fork
    from usd_garment.usd.read import read_smpl_motion

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    if not can_fork():
        pytest.skip("the posing workers are forked")
    submitted: list[int] = []
    submit = PosingPool.submit

    def spy(pool: PosingPool, x: torch.Tensor, *args: Any) -> Any:
        submitted.append(len(x))
        return submit(pool, x, *args)

    monkeypatch.setattr(PosingPool, "submit", spy)
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 11, 30.0, seed=4, body=body_model), body_model)
    motion, _ = read_smpl_motion(body, body_model)
    template = load_template("tshirt", "low")
    config = json.loads((learned.shipped_model("tshirt") / "model.json").read_text())
    models = {}
    for name, seconds in (("plain", 0.0), ("smoothed", 1 / 30)):
        models[name] = tmp_path / name
        shutil.copytree(learned.shipped_model("tshirt"), models[name])
        (models[name] / "model.json").write_text(
            json.dumps({**config, "posed_smoothing_s": seconds})
        )

    def streams(name: str, chunk: int = 3) -> tuple[list[np.ndarray], list[np.ndarray], Any]:
        """The garment of one process and of two workers, and the method with the workers."""
        one = list(learned.LearnedPreimageMethod(models[name]).predict_stream(
            motion, body_model, template, chunk,
        ))  # fmt: skip
        method = learned.LearnedPreimageMethod(models[name])
        method.workers = 2
        submitted.clear()
        return one, list(method.predict_stream(motion, body_model, template, chunk)), method

    threads = torch.get_num_threads()
    # Both at one thread, as each worker runs: at two threads this process's products may round
    # otherwise, the rows of a matrix product split between the threads (the GRU's latent codes
    # of the last three frames here on a 2-core EPYC, stop 89; 3e-8 m on 2 % of the posed
    # coordinates on a 2-core Xeon, stop 85).
    torch.set_num_threads(1)
    try:
        one, two, method = streams("plain")
        assert submitted == [3, 3, 3, 2] and [len(p) for p in two] == [3, 3, 3, 2]
        np.testing.assert_array_equal(np.concatenate(two), np.concatenate(one))
        assert method.seconds["workers"] > 0
        submitted.clear()
        three = list(method.predict_stream(motion, body_model, template, 4))  # three chunks
        assert submitted == [] and [len(p) for p in three] == [4, 4, 3]
        assert method.seconds["workers"] == 0 and method.seconds["preimage"] > 0
        # A posed smoothing: each chunk goes with the frames around it and comes back alone.
        one, two, method = streams("smoothed")
        assert submitted == [7, 10, 9, 6] and [len(p) for p in two] == [3, 3, 3, 2]  # 4 around
        np.testing.assert_array_equal(np.concatenate(two), np.concatenate(one))
    finally:
        torch.set_num_threads(threads)
    # At this process's own threads: the workers' garment the same to rounding, and the
    # threads this process gave up while they ran (_threads_beside) given back.
    one, two, method = streams("plain")
    np.testing.assert_allclose(np.concatenate(two), np.concatenate(one), atol=1e-6)
    assert torch.get_num_threads() == threads and method.seconds["workers"] > 0


def test_coarser_levels_of_a_pushing_method_are_dressed_not_carried(
    body_model: BodyModel, synthetic_body: BodyModel, tmp_path: Path
) -> None:
    """With ``learned+preimage`` the lod variants and the proxy are what ``dress --lod`` writes
    at their level (the method dresses them), not the computed garment carried down after its
    push (which can be inside the body again between the vertices the push moved)."""
    from pxr import Usd, UsdGeom

    from usd_garment.dress import dress
    from usd_garment.garment.lod import carry_to_lod

    if body_model is synthetic_body:
        pytest.skip("needs the embedded default body and its fields")
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 4, 30.0, seed=4, body=body_model), body_model)
    out = tmp_path / "v.usdc"
    dress(body, out, method="learned+preimage", lod="medium", lod_variants=True, proxy_lod="low")
    medium, _, info = read_garment_layer(out)
    m = info.canonical_to_local
    stage = Usd.Stage.Open(str(out))
    garment = stage.GetPrimAtPath(info.mesh)
    garment.GetVariantSet("lod").SetVariantSelection("low")
    times = info.time_codes.tolist()
    low_variant = UsdGeom.Mesh(garment).GetPointsAttr()
    proxy = UsdGeom.Mesh(stage.GetPrimAtPath(info.mesh + "_proxy")).GetPointsAttr()
    dress(body, tmp_path / "low.usdc", method="learned+preimage", lod="low")
    low = read_garment_layer(tmp_path / "low.usdc")[0] @ m[:3, :3] + m[3, :3]
    for attr in (low_variant, proxy):
        local = np.stack([np.asarray(attr.Get(t)) for t in times])
        np.testing.assert_allclose(local, low, atol=1e-5)
    carried = carry_to_lod(medium, "tshirt", "medium", "low") @ m[:3, :3] + m[3, :3]
    assert np.abs(carried - low).max() > 1e-4


def test_the_methods_that_push_vertices_out_say_so() -> None:
    """``dress`` dresses coarser levels with exactly the methods that move posed vertices out of
    the body one by one; the others' garments are carried down."""
    from usd_garment.methods import available_methods, get_method
    from usd_garment.methods.base import pushes_vertices

    pushing = {m for m in available_methods() if pushes_vertices(get_method(m))}
    assert pushing == {"lbs+postprocess", "learned+preimage", "learned+postprocess"}


def test_posed_smoothing_keeps_a_vertex_out_of_its_own_part() -> None:
    """A vertex 2.5 mm outside a ball that it circles by 20° a frame: its smoothed positions
    (a Gaussian of one frame) cut into the ball (the mean of points on an arc lies inside
    it); with the canonical body's SDF each is moved back ε = 2 mm out, along with the point
    before skinning that skins to it; frames of the motion around the chunk take part."""
    from usd_garment.generative.losses import COLLISION_EPSILON
    from usd_garment.methods.learned_posing import Smoothing

    smoothing = Smoothing.of(1 / 30, 30.0)
    assert smoothing.sigma == 1.0 and smoothing.radius == 4
    assert Smoothing.of(1 / 60, 30.0).radius == 2 and Smoothing().radius == 0
    angle = torch.arange(13, dtype=torch.float32) * (20 * np.pi / 180)
    circle = torch.stack([torch.cos(angle), torch.sin(angle), torch.zeros(13)], -1)
    x = (0.1025 * circle)[:, None]  # (13, 1, 3): one vertex, skinned by one joint, unmoved
    eye = torch.eye(4)[:3].expand(13, 1, 3, 4)
    posed = (x, x, [eye])  # one piece of 13 frames, blended by the identity

    def ball(p: torch.Tensor) -> torch.Tensor:
        return p.norm(dim=-1) - 0.1

    core = slice(4, 9)
    cut, _ = smoothing.apply(x, posed, core, None)
    assert bool((cut.norm(dim=-1) < 0.1).all())  # inside the ball on every frame
    whole = torch.from_numpy(gaussian_filter1d(x.numpy(), 1.0, axis=0, mode="nearest"))
    torch.testing.assert_close(cut, whole[core])
    kept, unposed = smoothing.apply(x, posed, core, ball)
    # A floor under the decoded garment's SDF (its 2.5 mm) changes nothing; one that (wrongly)
    # says 1 m spares the lookups, and the vertex stays cut.
    assert torch.equal(smoothing.apply(x, posed, core, ball, torch.full((13, 1), 2.5e-3))[0], kept)
    assert torch.equal(smoothing.apply(x, posed, core, ball, torch.ones(13, 1))[0], cut)
    # Posed in two pieces that the core's frames straddle: the same.
    assert torch.equal(smoothing.apply(x, (x, x, [eye[:6], eye[6:]]), core, ball)[0], kept)
    torch.testing.assert_close(kept.norm(dim=-1), torch.full((5, 1), 0.1 + COLLISION_EPSILON))
    torch.testing.assert_close(unposed, kept)  # the identity skins it to itself
    direction = cut / cut.norm(dim=-1, keepdim=True)
    torch.testing.assert_close(kept / kept.norm(dim=-1, keepdim=True), direction)  # straight out
    plain, same = Smoothing().apply(x, posed, core, ball)
    assert torch.equal(plain, x[core]) and torch.equal(same, x[core])


def test_posed_smoothing_stops_at_the_cuts() -> None:
    """A garment that jumps 0.5 m at a cut (a restart, where another motion starts:
    ``motion_restarts``) is smoothed on each side of it on its own, the nearest frame repeated
    there as at the motion's ends: no frame is carried towards the other side (across the jump,
    a Gaussian of one frame would move the frames beside it 0.12 m); a chunk is smoothed as the
    whole motion with the cuts ``Smoothing.within`` it."""
    from usd_garment.methods.learned_posing import Smoothing

    frames = torch.arange(20, dtype=torch.float32)
    x = torch.stack([0.01 * frames, torch.zeros(20), torch.zeros(20)], -1)[:, None]  # (20, 1, 3)
    x[10:, 0, 2] += 0.5  # the jump: frames 10 on
    posed = (x, x, [torch.eye(4)[:3].expand(20, 1, 3, 4)])
    whole = Smoothing.of(1 / 30, 30.0, (10,))
    smoothed, _ = whole.apply(x, posed, slice(0, 20), None)
    runs = [
        gaussian_filter1d(x[a:b].numpy(), 1.0, axis=0, mode="nearest")
        for a, b in ((0, 10), (10, 20))
    ]
    torch.testing.assert_close(smoothed, torch.from_numpy(np.concatenate(runs)))
    assert float((smoothed - x)[..., 2].abs().max()) == 0.0  # nothing across the jump
    assert float((smoothed - x).norm(dim=-1).max()) < 0.01  # a run's ends: within a step
    crossed, _ = Smoothing.of(1 / 30, 30.0).apply(x, posed, slice(0, 20), None)
    assert float((crossed - x).norm(dim=-1).max()) > 0.1
    # The frames 7..13 of the motion as a chunk with the radius (4) around them, 3..17: the cut
    # at its frame 7 (beyond it, none).
    assert whole.within(3, 17) == Smoothing(1.0, (7,)) and whole.within(10, 20).cuts == ()
    piece = (x[3:17], x[3:17], [posed[2][0][3:17]])
    chunk, _ = whole.within(3, 17).apply(x[3:17], piece, slice(4, 10), None)
    torch.testing.assert_close(chunk, smoothed[7:13])


def _screw(count: int, jump: torch.Tensor, at: int) -> torch.Tensor:
    """``(count, 4, 4)`` float64: a root that turns 3° about +Y and moves 2 cm along its own x
    and 1 cm along its own z a frame (the same step in its own frame each time), moved by
    ``jump`` ``(4, 4)`` from frame ``at`` on."""
    angle = 3 * np.pi / 180
    step = torch.eye(4, dtype=torch.float64)
    step[0, 0], step[0, 2], step[2, 0], step[2, 2] = (
        np.cos(angle), np.sin(angle), -np.sin(angle), np.cos(angle),
    )  # fmt: skip
    step[0, 3], step[2, 3] = 0.02, 0.01
    root = [torch.eye(4, dtype=torch.float64)]
    for _ in range(count - 1):
        root.append(root[-1] @ step)
    moved = torch.stack(root)
    moved[at:] = jump @ moved[at:]
    return moved


def test_posed_smoothing_takes_a_root_jump_out() -> None:
    """Points carried by a root that teleports 0.5 m and turns 90° at frame 10 (a jump of the
    root alone: ``root_cuts``, no restart) are smoothed across it as the jump-free motion would
    be, the jump put back after: the frames before it as the jump-free ones, those after as the
    jump-free ones moved; ``RootJump.at`` finds the jump exactly where the root's steps before
    and after it (met midway, or the one after where a cut leaves none before) are the steps
    around it; a chunk is smoothed as the whole motion with the jumps ``Smoothing.within`` it."""
    from usd_garment.methods.learned_posing import Smoothing
    from usd_garment.motion.jumps import RootJump

    turn = torch.tensor(
        [[0.0, 0.0, 1.0, 0.5], [0.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.1], [0.0, 0.0, 0.0, 1.0]],
        dtype=torch.float64,
    )
    still, root = _screw(20, torch.eye(4, dtype=torch.float64), 0), _screw(20, turn, 10)
    local = torch.tensor([[0.1, 0.3, 0.0, 1.0], [-0.2, 0.1, 0.15, 1.0]], dtype=torch.float64)
    x = torch.einsum("tab,nb->tna", root, local)[..., :3].float()  # (20, 2, 3) the points carried
    plain = torch.einsum("tab,nb->tna", still, local)[..., :3].float()
    jump = RootJump.at(10, root.numpy())
    undo = torch.tensor(jump.undo, dtype=torch.float64).reshape(3, 4)
    torch.testing.assert_close(undo, torch.linalg.inv(turn)[:3], atol=1e-6, rtol=0)
    # The step after the jump where the one before it crosses another cut: the same here.
    after = torch.tensor(RootJump.at(10, root.numpy(), cuts=(9,)).undo)
    torch.testing.assert_close(after, torch.tensor(jump.undo), atol=1e-6, rtol=0)
    eye = torch.eye(4)[:3].expand(20, 2, 3, 4)
    whole = Smoothing.of(1 / 30, 30.0, (), (jump,))
    smoothed, _ = whole.apply(x, (x, x, [eye]), slice(0, 20), None)
    free = torch.from_numpy(gaussian_filter1d(plain.numpy(), 1.0, axis=0, mode="nearest"))
    torch.testing.assert_close(smoothed[:10], free[:10], atol=1e-6, rtol=0)
    moved = free[10:] @ turn[:3, :3].float().T + turn[:3, 3].float()
    torch.testing.assert_close(smoothed[10:], moved, atol=1e-6, rtol=0)
    # Stopped at the jump as at a restart, the frames beside it are held back (7-13 mm).
    held, _ = Smoothing.of(1 / 30, 30.0, (10,)).apply(x, (x, x, [eye]), slice(0, 20), None)
    assert float((held[9] - smoothed[9]).norm(dim=-1).min()) > 0.005
    # The frames 7..13 as a chunk with the radius (4) around them, 3..17: the jump at its frame 7.
    assert whole.within(3, 17) == Smoothing(1.0, (), (RootJump(7, jump.undo),))
    assert whole.within(10, 20).jumps == ()
    chunk, _ = whole.within(3, 17).apply(
        x[3:17], (x[3:17], x[3:17], [eye[3:17]]), slice(4, 10), None
    )
    torch.testing.assert_close(chunk, smoothed[7:13], atol=1e-6, rtol=0)
