"""``usd-garment bench``: every method × level of detail on the same inputs, a row per run with
speed and the collision and error figures, the Pareto front, the pictures, and failures reported
as rows instead of ending the run."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.eval.bench import (
    REFERENCE_LABEL,
    BenchInput,
    BenchMethod,
    BenchRow,
    chart_points,
    chart_table,
    load_report,
    pareto_front,
    run_bench,
    simulated_rows,
)
from usd_garment.methods.budget import load_budget
from usd_garment.methods.learned import shipped_model
from usd_garment.methods.learned_model import model_identity
from usd_garment.motion.procedural import make_motion
from usd_garment.usd.body_layer import write_body_layer

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory, body_model: BodyModel) -> Path:
    path = tmp_path_factory.mktemp("bench") / "walk.usdc"
    write_body_layer(path, make_motion("walk", 6, seed=1, body=body_model), body_model)
    return path


def test_pareto_front_keeps_the_points_nothing_beats() -> None:
    speed = [10.0, 100.0, 1000.0, 50.0, 1000.0, float("nan")]
    cost = [0.1, 0.5, 2.0, 0.6, 3.0, 0.0]
    # 3 is beaten by 1 (faster and cheaper), 4 by 2 (as fast, cheaper), 5 has no speed.
    assert pareto_front(speed, cost) == [0, 1, 2]


def test_bench_command_writes_table_chart_and_curves(tmp_path: Path, walk: Path) -> None:
    reference = tmp_path / "reference.usdc"
    result = CliRunner().invoke(
        main, ["dress", str(walk), "-o", str(reference), "--method", "lbs", "--lod", "low"]
    )
    assert result.exit_code == 0, result.output
    report = tmp_path / "report"
    args = ["bench", str(walk), "--reference", str(reference), "--method", "lbs", "--method",
            "lbs+postprocess", "--lod", "low", "--lod", "medium", "-o", str(report)]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "5 runs in" in result.output  # 2 methods x 2 levels of detail, and the reference
    for name in ("report.json", "report.csv", "chart.png", "collisions.png"):
        assert (report / name).stat().st_size > 0, name
    with open(report / "report.csv") as handle:
        rows = {(r["method"], r["lod"]): r for r in csv.DictReader(handle)}
    reference = rows.pop(("simulation (reference)", "-"))
    assert int(reference["frames"]) == 6 and reference["frames_per_second"] == ""
    assert set(rows) == {(m, lod) for m in ("lbs", "lbs+postprocess") for lod in ("low", "medium")}
    assert all(int(r["frames"]) == 6 and float(r["frames_per_second"]) > 0 for r in rows.values())
    # Error against the reference (low): zero for itself; at medium, the reference is carried
    # to the medium mesh first (both skinned the same way: well under a millimetre apart).
    assert float(rows["lbs", "low"]["reference_mm"]) == pytest.approx(0.0, abs=1e-4)
    assert float(rows["lbs+postprocess", "low"]["reference_mm"]) >= 0.0
    assert 0.0 < float(rows["lbs", "medium"]["reference_mm"]) < 1.0
    # The whole garment's mean offset is part of the error: never more than it.
    for r in rows.values():
        assert 0.0 <= float(r["reference_shift_mm"]) <= float(r["reference_mm"]) + 1e-6
    # The push-out leaves no vertex inside elsewhere, lbs may; both are measured per frame.
    assert float(rows["lbs+postprocess", "low"]["inside_elsewhere_share"]) <= float(
        rows["lbs", "low"]["inside_elsewhere_share"]
    )
    payload = json.loads((report / "report.json").read_text())
    assert len(payload["chart"]) == 5 and payload["wall_seconds"] > 0
    # Where the vertices inside elsewhere are: a part list exactly where there are some.
    for r in payload["rows"]:
        shares = r["elsewhere_by_part"]
        assert bool(shares) == (r["summary"]["inside_elsewhere_share"] > 0), r["label"]
        assert not shares or sum(shares.values()) == pytest.approx(1.0)
    assert rows["lbs+postprocess", "low"]["elsewhere_parts"] == ""
    assert all(len(r["inside_elsewhere"]) == 6 for r in payload["rows"])
    again = load_report(report / "report.json")  # the chart can be redrawn from the report
    assert [(r.label, r.lod) for r in again] == [(r["label"], r["lod"]) for r in payload["rows"]]
    table = chart_table(again).splitlines()
    assert len(table) == 6 and table[1].split()[0] == "simulation"
    assert table[0].split()[-3:] == ["offset", "accel", "failed"]
    with pytest.raises(ValueError, match="not a bench report"):
        load_report(report / "report.csv")
    # The error table of dress --error-budget: each method x level of detail with its error.
    budget = load_budget(report / "budget.json")
    assert {(e.method, e.lod) for e in budget} == set(rows)
    for e in budget:
        assert e.error_mm == pytest.approx(float(rows[e.method, e.lod]["reference_mm"]), abs=1e-4)
    source = json.loads((report / "budget.json").read_text())["source"]
    assert source["command"].endswith("bench") and source["options"]["lods"] == ["low", "medium"]
    assert "model" not in source  # no learned entry: no model to name
    # What measured the speeds: the processor and its readings, so sessions can be compared.
    assert "cores" in source["machine"] and "torch" in source["machine"]
    readings = source["speed_readings"]
    assert set(readings) == {"large_add_ms", "small_op_us", "matmul_gflops"}
    assert all(math.isfinite(v) and v > 0 for v in readings.values())


def test_a_failing_method_is_a_row_not_the_end(tmp_path: Path, walk: Path) -> None:
    methods = [
        BenchMethod("broken", "learned", tmp_path / "no_model", lods=("low",)),
        BenchMethod("lbs", "lbs", lods=("low",)),
    ]
    rows = run_bench([BenchInput("walk", walk)], methods, tmp_path / "out")
    assert [r.label for r in rows] == ["broken", "lbs"]
    assert rows[0].error.startswith("ModelError") and rows[0].frames == 0
    assert not rows[1].error and np.isfinite(rows[1].frames_per_second)


def test_a_model_is_benched_with_each_model_method(tmp_path: Path, walk: Path) -> None:
    model = shipped_model("tshirt")
    assert model is not None
    args = ["bench", str(walk), "--method", "learned", "--method", "lbs", "--lod", "low",
            "--model", f"cand={model}", "--model-method", "learned", "--model-method",
            "learned+canonical", "-o", str(tmp_path / "r")]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    rows = json.loads((tmp_path / "r" / "report.json").read_text())["rows"]
    assert [(r["label"], r["method"], r["lod"]) for r in rows] == [
        ("learned", "learned", "high"),  # the shipped model
        ("learned", "learned", "low"),
        ("cand", "learned", "high"),
        ("cand", "learned", "low"),  # carried down to the --lod asked for
        ("cand+canonical", "learned+canonical", "high"),
        ("cand+canonical", "learned+canonical", "low"),
        ("lbs", "lbs", "low"),
    ]
    assert not any(r["error"] for r in rows)
    # The error table names the model its learned entries were measured with: the shipped one.
    source = json.loads((tmp_path / "r" / "budget.json").read_text())["source"]
    assert source["model"] == model_identity(model)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--model", "nolabel"], "expected LABEL=DIR"),
        (["--reference", "a.usdc", "--reference", "b.usdc"], "one --reference per INPUT"),
        (["--model", "x=no_such_model"], "not a model directory"),
        (["--capture", "clip.bvh"], "--capture is for --stress"),
    ],
)
def test_bench_bad_input(tmp_path: Path, walk: Path, extra: list[str], message: str) -> None:
    result = CliRunner().invoke(main, ["bench", str(walk), "-o", str(tmp_path / "r"), *extra])
    assert result.exit_code != 0 and message in result.output, result.output
    assert "Traceback" not in result.output and not (tmp_path / "r").exists()


def test_stress_inputs_are_what_they_say(tmp_path: Path, body_model: BodyModel) -> None:
    from usd_garment.eval.stress import STRESS_FRAMES, stress_motions, write_stress_inputs
    from usd_garment.usd.read import read_smpl_motion

    names = ["shape_beta1_plus3", "fast_x4", "root_jumps", "joint_splice", "long_40"]
    inputs = write_stress_inputs(tmp_path, body_model, long_frames=40, names=names)
    assert [case.name for case in inputs] == names
    motions = {case.name: read_smpl_motion(case.body, body_model)[0] for case in inputs}
    assert motions["shape_beta1_plus3"].betas[0] == pytest.approx(3.0)
    assert motions["long_40"].num_frames == 40
    assert motions["fast_x4"].num_frames == 2 * STRESS_FRAMES and motions["fast_x4"].fps == 30
    # The root jumps: 0.5 m sideways in one frame, the heading snapped by 90 degrees.
    step = np.linalg.norm(np.diff(motions["root_jumps"].trans, axis=0), axis=1)
    assert step.max() > 0.45 and np.sort(step)[-2] < 0.1
    # The splice: the walk's root, another motion's joints from frame 45, the cut declared.
    splice, walk = motions["joint_splice"], motions["root_jumps"]
    assert splice.cut_times == (45.0,) and not motions["root_jumps"].cut_times
    np.testing.assert_allclose(splice.trans[:30], walk.trans[:30], atol=1e-5)
    assert np.abs(np.diff(splice.pose[:, 1:], axis=0)).max(axis=(1, 2)).argmax() == 44
    made = stress_motions(body_model, long_frames=40)
    assert set(made) >= set(names) | {"arms_folded", "hands_on_hips", "fast_x2"}
    with pytest.raises(ValueError, match="unknown stress case 'nope'"):
        write_stress_inputs(tmp_path, body_model, names=["nope"])


@pytest.mark.parametrize("garment", ["tshirt", "dress"])
def test_the_judge_script_benches_a_candidate_as_the_rules_did(
    garment: str, tmp_path: Path
) -> None:
    """``examples/train/judge.sh``: gate 1 on v4's validation split; the fresh set (the eight
    kinds, seeds FIRST..FIRST+7, each on a random shape, 150 frames, the garment simulated on
    each) made once and benched against its simulations in order; then the reported benches.
    Each is the candidate under its label beside the shipped model, networks alone, at high."""
    from tests.script_calls import script_calls
    from usd_garment.cli.bench import bench

    args = (garment, "scratch/models/X", "1021", "scratch/judge")
    calls = script_calls("judge.sh", *args, tmp_path=tmp_path)
    benches = {}
    for call in calls:
        if call[0] == "bench":
            params = bench.make_context("bench", call[1:]).params
            benches[params["output"].name] = params
    assert list(benches) == ["val", "shapes", "test", "arms", "members"]
    for params in benches.values():
        assert params["garment"] == garment and params["lods"] == ("high",)
        assert "learned" in params["names"] and "X=scratch/models/X" in params["models"]
    v4 = Path(f"scratch/dataset_{garment}_v4")
    assert (benches["val"]["manifest"], benches["val"]["split_names"]) == (v4, "validation")
    assert (benches["test"]["manifest"], benches["test"]["split_names"]) == (v4, "test")
    kinds = ["walk", "run", "jumping_jacks", "arm_swing", "arm_raise", "torso_twist",
             "torso_bend", "squat"]  # fmt: skip
    made = sorted(c[2:] for c in calls if c[:2] == ["motion", "make"])
    fresh = Path("scratch/judge/shapes_test")
    assert made == sorted(
        [kind, "--frames", "150", "--seed", str(1021 + k), "--betas", "random", "-o",
         str(fresh / f"{kind}_{1021 + k}.usdc")]
        for k, kind in enumerate(kinds)
    )  # fmt: skip
    simulated = {c[1]: c[c.index("-o") + 1] for c in calls if c[0] == "simulate"}
    assert all(c[c.index("--garment") + 1] == garment for c in calls if c[0] == "simulate")
    names = [f"{kind}_{1021 + k}" for k, kind in enumerate(kinds)]
    assert simulated == {
        str(fresh / f"{n}.usdc"): str(fresh / f"{n}_{garment}.usdc") for n in names
    }
    shapes = benches["shapes"]
    assert shapes["inputs"] == tuple(fresh / f"{n}.usdc" for n in names)
    assert shapes["references"] == tuple(fresh / f"{n}_{garment}.usdc" for n in names)
    assert benches["arms"]["names"] == ("learned", "lbs")
    members = benches["members"]
    assert members["inputs"] == (v4 / "c01_s0_body.usdc", v4 / "c02_s0_body.usdc")
    assert len(members["models"]) == 7  # the candidate and both models' three members
    imported = [c for c in calls if c[0] == "import-bvh"]
    assert [c[c.index("--collars") + 1] for c in imported] == ["rest"]
    (tmp_path / "aimed").mkdir()
    again = script_calls("judge.sh", *args, tmp_path=tmp_path / "aimed", env={"COLLARS": "aimed"})
    assert [c[c.index("--collars") + 1] for c in again if c[0] == "import-bvh"] == ["aimed"]


def test_simulated_rows_pool_the_inputs_with_a_simulation_only() -> None:
    """``simulated_rows``: the rows of the inputs whose reference simulation was read (the
    paper's Table 1 pools its figures over these); an input without one, or whose reference
    failed, is left out, so its collisions no longer weigh in the chart point."""

    def row(name: str, label: str, share: float, error: str = "") -> BenchRow:
        return BenchRow(name, label, label, "high", frames=10,
                        summary={"inside_elsewhere_share": share}, error=error)  # fmt: skip

    rows = [
        row("walk", "lbs", 0.4),
        row("run", "lbs", 0.1),
        row("run", REFERENCE_LABEL, 0.0),
        row("bad", "lbs", 0.9),
        row("bad", REFERENCE_LABEL, 0.0, error="OSError: gone"),
    ]
    kept = simulated_rows(rows)
    assert [(r.input, r.label) for r in kept] == [("run", "lbs"), ("run", REFERENCE_LABEL)]
    (point,) = [p for p in chart_points(kept) if p.label == "lbs"]
    assert point.frames == 10 and point.inside_elsewhere_share == pytest.approx(0.1)
