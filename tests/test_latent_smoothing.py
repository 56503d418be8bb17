"""The time filter of a model's latent codes: the Gaussian itself, its place in the model
directory (``latent_smoothing``, set by ``usd-garment train smooth``) and in the prediction."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from click.testing import CliRunner

from tests.models import untrained_model
from usd_garment.body.io import load_body_model
from usd_garment.cli.main import main
from usd_garment.garment.library import load_template
from usd_garment.methods.learned import predict_latents, smooth_codes
from usd_garment.methods.learned_model import ModelError, load_learned_model, save_learned_model
from usd_garment.motion.procedural import make_motion


def test_the_filter_keeps_constants_and_lines_and_spreads_a_step() -> None:
    t = torch.arange(40, dtype=torch.float32)
    values = torch.stack([torch.full_like(t, 2.5), 0.1 * t, (t >= 20).float()], dim=1)
    out = smooth_codes(values, 2.0)
    assert out.shape == values.shape
    torch.testing.assert_close(out[:, 0], values[:, 0])
    torch.testing.assert_close(out[6:-6, 1], values[6:-6, 1])  # 3σ from the ends
    step = out[:, 2]
    assert bool((step.diff() >= -1e-7).all()) and 0.4 < float(step[19]) < 0.5 < float(step[20])
    assert torch.equal(smooth_codes(values, 0.0), values)
    assert torch.equal(smooth_codes(values[:1], 3.0), values[:1])


def test_train_smooth_writes_the_filter_that_prediction_applies(tmp_path: Path) -> None:
    body = load_body_model()
    source, out = tmp_path / "model", tmp_path / "smooth"
    save_learned_model(source, untrained_model(body, load_template("tshirt", "low"), 0))
    result = CliRunner().invoke(
        main, ["train", "smooth", str(source), "--sigma", "1.5", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    config = json.loads((out / "model.json").read_text())
    assert config["latent_smoothing"] == 1.5
    assert config["smoothing_command"].startswith("usd-garment train smooth")
    plain, smoothed = load_learned_model(source), load_learned_model(out)
    assert plain.smoothing == 0.0 and smoothed.smoothing == 1.5

    motion = make_motion("arm_swing", 45, 30.0, seed=4, body=body)
    raw = predict_latents(plain, motion)
    torch.testing.assert_close(predict_latents(smoothed, motion), smooth_codes(raw, 1.5))

    config["latent_smoothing"] = -1.0
    (out / "model.json").write_text(json.dumps(config))
    with pytest.raises(ModelError, match="latent_smoothing"):
        load_learned_model(out)
