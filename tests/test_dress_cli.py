"""``usd-garment dress`` and ``eval`` from the command line: a JSON summary on stdout, and bad
input or output giving one line of error, a non-zero exit, no output file and an untouched input."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from tests.dress_helpers import random_motion, strong_motion
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.garment.library import load_template
from usd_garment.methods.learned import default_method
from usd_garment.usd.body_layer import write_body_layer

BAD_INPUTS = sorted((Path(__file__).parent / "data" / "bad").glob("*.usd*"))


@pytest.fixture
def body_layer(tmp_path: Path, body_model: BodyModel) -> Path:
    path = tmp_path / "in" / "body.usda"
    path.parent.mkdir()
    write_body_layer(path, random_motion(frames=6), body_model)
    return path


def _run(args: list[str]) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(result.exception, AssertionError)
    return result.exit_code, result.stdout, result.stderr


def test_dress_json_summary_and_eval(body_layer: Path, tmp_path: Path) -> None:
    out = tmp_path / "tshirt.usdc"
    code, stdout, _ = _run(["dress", body_layer, "-o", out, "--frames", "1:5", "--lod", "low",
                            "--root-layer", tmp_path / "root.usda", "--json"])  # fmt: skip
    assert code == 0, stdout
    summary = json.loads(stdout)
    assert summary["frames"] == 4
    assert summary["method"] == default_method("tshirt", "low") and summary["garment"] == "tshirt"
    assert set(summary["seconds"]) == {"read", "compute", "write"}
    assert summary["outputs"] == [str(out), str(tmp_path / "root.usda")]
    assert out.is_file()

    code, stdout, _ = _run(["eval", out, "--body", body_layer, "--reference", out, "--json"])
    assert code == 0, stdout
    report = json.loads(stdout)
    assert report["time_codes"] == [1.0, 2.0, 3.0, 4.0]
    assert report["summary"]["reference_mm"] == 0.0
    assert report["summary"]["nan_count"] == 0
    assert len(report["per_frame"]["inside_share"]) == 4

    code, stdout, _ = _run(["eval", out, "--body", body_layer])
    assert code == 0 and "vertices inside the body" in stdout


def _assert_clean_failure(
    args: list[str], folder: Path, source: Path | None, exit_code: int | None = None
) -> str:
    before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    digest = hashlib.sha256(source.read_bytes()).hexdigest() if source and source.exists() else None
    code, stdout, stderr = _run(args)
    assert code != 0 and (exit_code is None or code == exit_code), code
    message = stderr.strip()
    assert message.startswith("Error:") and "\n" not in message, message
    assert "Traceback" not in stdout + stderr
    assert {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()} == before
    if digest is not None:
        assert hashlib.sha256(source.read_bytes()).hexdigest() == digest
    return message


@pytest.mark.parametrize("bad", BAD_INPUTS, ids=lambda p: p.name)
def test_bad_input_files(bad: Path, tmp_path: Path) -> None:
    source = tmp_path / bad.name
    shutil.copy(bad, source)
    _assert_clean_failure(["dress", source, "-o", tmp_path / "g.usdc"], tmp_path, source)


def test_bad_corpus_is_there() -> None:
    assert len(BAD_INPUTS) >= 5
    assert set(EXPECTED_ERRORS) <= {p.name for p in BAD_INPUTS}


#: The one-line error ``dress`` gives for inputs that UsdSkel reads without complaint (or only
#: with a warning), after the file name and skeleton path.
EXPECTED_ERRORS = {
    "wrong_count_rotations.usda": "the SkelAnimation /Char/Skel/Anim has 23 rotations for its "
    "24 joints at time code 1",
    "wrong_count_translations.usda": "the SkelAnimation /Char/Skel/Anim has 23 translations for "
    "its 24 joints at time code 1",
    "wrong_count_scales.usda": "the SkelAnimation /Char/Skel/Anim has 23 scales for its 24 "
    "joints at time code 1",
    "huge_betas.usda": "smpl:betas: betas[0] = 1e+06 is outside the body's shape space "
    "(|beta| <= 5)",
    "nan_cuts.usda": "smpl:cuts holds a time code that is not finite",
    "no_animation_values.usda": "no animation: the SkelAnimation /Char/Skel/Anim has no time "
    "samples and no default values on its rotations and translations",
}


@pytest.mark.parametrize("name", sorted(EXPECTED_ERRORS))
def test_bad_input_error_lines(name: str, tmp_path: Path) -> None:
    source = tmp_path / name
    shutil.copy(Path(__file__).parent / "data" / "bad" / name, source)
    out = tmp_path / "g.usdc"
    message = _assert_clean_failure(["dress", source, "-o", out], tmp_path, source, exit_code=1)
    assert message == f"Error: {source}:/Char/Skel: {EXPECTED_ERRORS[name]}"
    assert not out.exists()


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["-o", "{dir}/missing/g.usdc"], "does not exist"),
        (["-o", "{input}"], "overwrite the input"),
        (["-o", "{dir}/in/../in/body.usda"], "overwrite the input"),
        (["-o", "{dir}/g.obj"], ".usdc"),
        (["-o", "{dir}/g.usdc", "--method", "magic"], "unknown method"),
        (["-o", "{dir}/g.usdc", "--garment", "hat"], "unknown garment"),
        (["-o", "{dir}/g.usdc", "--frames", "0:999"], "frames"),
        (["-o", "{dir}/g.usdc", "--skeleton", "/Nope"], "/Nope"),
        (["-o", "{dir}/g.usdc", "--root-layer", "{input}"], "overwrite the input"),
        (["-o", "{dir}/g.usdc", "--body-model", "{dir}/none.npz"], "none.npz"),
        (["-o", "{dir}/g.usdc", "--betas", "0,9"], "betas given: betas[1] = 9 is outside"),
        (["-o", "{dir}/g.usdc", "--betas", "-1e6"], "outside the body's shape space"),
        (["-o", "{dir}/g.usdc", "--cut", "nan"], "a cut must be a finite time code"),
    ],
)
def test_bad_arguments(body_layer: Path, tmp_path: Path, extra: list[str], expected: str) -> None:
    args = ["dress", body_layer] + [a.format(dir=tmp_path, input=body_layer) for a in extra]
    message = _assert_clean_failure(args, tmp_path, body_layer)
    assert expected in message


def test_missing_input(tmp_path: Path) -> None:
    message = _assert_clean_failure(
        ["dress", tmp_path / "none.usda", "-o", tmp_path / "g.usdc"], tmp_path, None
    )
    assert "none.usda" in message


def test_eval_bad_layer(body_layer: Path, tmp_path: Path) -> None:
    message = _assert_clean_failure(["eval", body_layer, "--body", body_layer], tmp_path, None)
    assert "garment" in message


def test_quality_picks_the_level_of_detail(body_layer: Path, tmp_path: Path) -> None:
    out = tmp_path / "draft.usdc"
    result = CliRunner().invoke(main, ["dress", str(body_layer), "-o", str(out), "--quality",
                                       "draft", "--json"])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert json.loads(result.output)["vertices"] == len(load_template("tshirt", "low").vertices)
    both = CliRunner().invoke(main, ["dress", str(body_layer), "-o", str(tmp_path / "x.usdc"),
                                     "--quality", "final", "--lod", "low"])  # fmt: skip
    assert both.exit_code == 2 and "give --quality or --lod, not both" in both.output


def test_error_budget_picks_the_fastest_method_that_meets_it(
    body_layer: Path, tmp_path: Path
) -> None:
    from usd_garment.methods.budget import BUDGET_FILE, BudgetEntry, save_budget
    from usd_garment.methods.learned import shipped_model
    from usd_garment.methods.learned_model import model_identity

    model = tmp_path / "model"
    shutil.copytree(shipped_model("tshirt"), model)
    table = [  # method, lod, error mm, inside elsewhere, frames/s (as a bench would measure)
        BudgetEntry("learned", "high", 16.9, 0.008, 400.0),
        BudgetEntry("learned", "low", 17.2, 0.009, 700.0),
        BudgetEntry("lbs", "low", 38.0, 0.013, 900.0),
        BudgetEntry("lbs+postprocess", "high", 37.8, 0.0, 7.0),
    ]
    save_budget(model / BUDGET_FILE, table, {"command": "test"})
    picks = ((20, "learned", "low"), (50, "lbs", "low"), (17, "learned", "high"))
    for budget, method, lod in picks:
        out = tmp_path / f"b{budget}.usdc"
        code, stdout, _ = _run(["dress", body_layer, "-o", out, "--model", model,
                                "--error-budget", budget, "--json"])  # fmt: skip
        assert code == 0, stdout
        summary = json.loads(stdout)
        assert (summary["method"], summary["error_budget"]["lod"]) == (method, lod)
        assert summary["vertices"] == len(load_template("tshirt", lod).vertices)
    message = _assert_clean_failure(
        ["dress", body_layer, "-o", tmp_path / "b5.usdc", "--model", model, "--error-budget", 5],
        tmp_path, body_layer,
    )  # fmt: skip
    assert "no method meets an error of 5 mm" in message and "learned at high, 16.9 mm" in message
    # A table names the model it was measured with: the model's own is read, another refused.
    save_budget(model / BUDGET_FILE, table, {"command": "test", "model": model_identity(model)})
    assert _run(["dress", body_layer, "-o", tmp_path / "own.usdc", "--model", model,
                 "--error-budget", 20])[0] == 0  # fmt: skip
    other = {"version": "5", "weights": "0123456789abcdef"}
    save_budget(model / BUDGET_FILE, table, {"command": "test", "model": other})
    message = _assert_clean_failure(
        ["dress", body_layer, "-o", tmp_path / "b.usdc", "--model", model, "--error-budget", 20],
        tmp_path, body_layer,
    )  # fmt: skip
    assert "measured with another model (version 5, weights 0123456789abcdef)" in message
    renamed = {**model_identity(model), "version": "next"}  # the same networks, a new version
    save_budget(model / BUDGET_FILE, table, {"command": "test", "model": renamed})
    message = _assert_clean_failure(
        ["dress", body_layer, "-o", tmp_path / "b.usdc", "--model", model, "--error-budget", 20],
        tmp_path, body_layer,
    )  # fmt: skip
    assert f"measured with another model (version next, weights {renamed['weights']})" in message
    both = _run(["dress", body_layer, "-o", tmp_path / "x.usdc", "--error-budget", 20, "--lod",
                 "low"])  # fmt: skip
    assert both[0] == 2 and "give --error-budget or --lod, not both" in both[1] + both[2]
    (model / BUDGET_FILE).unlink()
    message = _assert_clean_failure(
        ["dress", body_layer, "-o", tmp_path / "b.usdc", "--model", model, "--error-budget", 20],
        tmp_path, body_layer,
    )  # fmt: skip
    assert "no error table" in message


def test_workers_give_the_results_of_one_process(tmp_path: Path, body_model: BodyModel) -> None:
    """``dress --workers 2`` writes the garment of one process, ``eval --workers 2`` prints its
    figures; a method that pushes nothing out of the body (lbs, learned) refuses the option."""
    from usd_garment.usd.garment_read import read_garment_layer

    body = tmp_path / "body.usda"
    write_body_layer(body, random_motion(frames=20), body_model)  # two blocks of 16 frames
    layers = []
    for workers in (1, 2):
        out = tmp_path / f"w{workers}.usdc"
        code, stdout, _ = _run(["dress", body, "-o", out, "--method", "lbs+postprocess",
                                "--lod", "low", "--workers", workers])  # fmt: skip
        assert code == 0, stdout
        layers.append(read_garment_layer(out)[0])
    np.testing.assert_array_equal(layers[1], layers[0])
    reports = []
    for workers in (1, 2):
        code, stdout, _ = _run(["eval", tmp_path / "w1.usdc", "--body", body, "--json",
                                "--workers", workers])  # fmt: skip
        assert code == 0, stdout
        reports.append(json.loads(stdout))
    assert reports[1] == reports[0]
    assert reports[0]["summary"]["inside_elsewhere_share"] == 0.0
    code, _, stderr = _run(["dress", body, "-o", tmp_path / "no.usdc", "--method", "lbs",
                            "--workers", "2"])  # fmt: skip
    assert code == 2 and "Invalid value for --workers" in stderr
    assert not (tmp_path / "no.usdc").exists()
    code, _, stderr = _run(["dress", body, "-o", tmp_path / "no.usdc", "--method", "learned",
                            "--workers", "2"])  # fmt: skip
    assert code == 2 and "learned pushes nothing out of the body" in stderr


def test_dress_of_the_template_shape_does_not_load_trimesh(
    tmp_path: Path, body_model: BodyModel
) -> None:
    """A body of the template shape (every BVH import's) needs no shape gap, so ``dress`` with
    the default method does not import trimesh (about 0.5 s of a fresh interpreter's start,
    a tenth of a 30-frame shot's wall time on a 2-core machine)."""
    body = tmp_path / "body.usda"
    write_body_layer(body, strong_motion(frames=4), body_model)
    code = (
        "import sys\n"
        "from usd_garment.cli.main import main\n"
        "main(['dress', sys.argv[1], '-o', sys.argv[2], '--lod', 'low'], standalone_mode=False)\n"
        "print('trimesh' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(body), str(tmp_path / "tshirt.usdc")],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert out.stdout.strip().splitlines()[-1] == "False"
    assert (tmp_path / "tshirt.usdc").is_file()
