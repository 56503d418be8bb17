"""``usd-garment dataset summary``: a manifest's simulation checks summed up per split, kind or
sequence (frame-weighted means, worst frames, counts against the ground truth's targets);
``dataset compare``: a set made again against the manifest it had."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from usd_garment.cli.main import main
from usd_garment.training.data_quality import compare_manifests, dataset_quality
from usd_garment.training.dataset import MANIFEST_FORMAT, MANIFEST_NAME


def _entry(name: str, split: str, kind: str, frames: int, **checks: Any) -> dict[str, Any]:
    base = {
        "inside_elsewhere_share_mean": 0.0, "inside_elsewhere_share_max": 0.0,
        "inside_forced_share_mean": 0.0, "inside_forced_share_max": 0.0, "nan_frames": 0,
        "bad_frames": 0, "retries": {}, "max_distance_m": 0.05, "stretch_p99_max": 1.1,
    }  # fmt: skip
    return {
        "name": name, "split": split, "motion_kind": kind, "capture": "", "frames": frames,
        "status": "ok", "checks": {**base, **checks}, "seconds": 60.0,
    }  # fmt: skip


@pytest.fixture
def manifest() -> dict[str, Any]:
    capture = _entry("c00_s0", "test", "capture", 300, max_distance_m=0.12, stretch_p99_max=1.25,
                     stretch_max=4.5)  # fmt: skip
    capture["capture"] = "/data/cmu_131_03.bvh"
    bad = {**_entry("m01_s0", "train", "run", 90), "status": "bad"}
    del bad["checks"]
    return {
        "format": MANIFEST_FORMAT,
        "sequences": [
            _entry("m00_s0", "train", "walk", 100, inside_elsewhere_share_mean=1e-3,
                   inside_elsewhere_share_max=6e-3, inside_forced_share_mean=2e-3,
                   retries={"12": 1, "13": 2}, bad_frames=1),
            _entry("m00_s1", "train", "walk", 300, inside_elsewhere_share_mean=2e-4,
                   inside_elsewhere_share_max=1e-3),
            bad,
            capture,
        ],
    }  # fmt: skip


def test_rows_are_frame_weighted_and_count_the_targets(manifest: dict[str, Any]) -> None:
    train, test, every = dataset_quality(manifest, "split")
    assert (train.group, train.sequences, train.ok, train.frames) == ("train", 3, 2, 400)
    assert train.elsewhere_mean == pytest.approx((100 * 1e-3 + 300 * 2e-4) / 400)
    assert train.forced_mean == pytest.approx(100 * 2e-3 / 400)
    assert (train.elsewhere_max, train.above_mean, train.above_frame) == (6e-3, 1, 1)
    assert (train.retried_frames, train.bad_frames, train.far) == (2, 1, 0)
    assert (test.far, test.max_distance_m, test.stretch_p99_max) == (1, 0.12, 1.25)
    # the largest edge: only the capture's entry records it (the others predate it)
    assert (train.stretch_max, test.stretch_max, every.stretch_max) == (None, 4.5, 4.5)
    assert (every.group, every.ok, every.frames, every.seconds) == ("all", 3, 700, 180.0)
    assert every.elsewhere_mean == pytest.approx((0.1 + 0.06) / 700)
    kinds = [row.group for row in dataset_quality(manifest, "kind")]
    assert kinds == ["walk", "run", "cmu_131_03", "all"]
    assert len(dataset_quality(manifest, "sequence")) == 5
    with pytest.raises(ValueError, match="unknown grouping"):
        dataset_quality(manifest, "shape")


def test_cli_table_json_and_errors(tmp_path: Path, manifest: dict[str, Any]) -> None:
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(manifest))
    runner = CliRunner()
    result = runner.invoke(main, ["dataset", "summary", str(tmp_path), "--by", "kind"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[3].startswith("cmu_131_03 | 1 / 1 | 300 |") and "| 12.0 (1) |" in lines[3]
    assert "| 1.250 (4.50) |" in lines[3] and "| 1.100 (–) |" in lines[1]
    assert lines[1].startswith("walk | 2 / 2 | 400 | 0.050 | 0.040 / 0.600 | 1 / 1 |")
    result = runner.invoke(main, ["dataset", "summary", str(tmp_path), "--json"])
    rows = json.loads(result.output)
    result = runner.invoke(main, ["dataset", "summary", str(tmp_path / MANIFEST_NAME), "--json"])
    assert json.loads(result.output) == rows  # the manifest file reads as its folder
    assert [r["group"] for r in rows] == ["train", "test", "all"] and rows[2]["frames"] == 700
    result = runner.invoke(main, ["dataset", "summary", str(tmp_path / "missing")])
    assert result.exit_code != 0 and "no dataset manifest" in result.output
    assert "Traceback" not in result.output


def test_compare_finds_the_sequences_that_changed(manifest: dict[str, Any]) -> None:
    again = json.loads(json.dumps(manifest))
    walk, walk1, run, capture = again["sequences"]
    walk["checks"]["retries"] = {"12": 1}  # one frame fewer retried
    walk["checks"]["inside_forced_share_mean"] = 2.5e-3
    walk1["seconds"] = 99.0  # time is not a figure of the simulation
    run.update(status="ok", checks=dict(capture["checks"]))  # the bad run now finishes
    del capture["checks"]["stretch_max"]  # a check one manifest lacks is not compared
    capture["checks"]["stretch_p99_max"] = 1.25
    again["sequences"] = [capture, walk, walk1, run]  # order: the new manifest's
    rows = compare_manifests(manifest, again)
    assert [(r.name, r.kind, r.changed) for r in rows] == [
        ("c00_s0", "cmu_131_03", ()), ("m00_s0", "walk", ("inside_forced_share_mean", "retries")),
        ("m00_s1", "walk", ()), ("m01_s0", "run", ("status",)),
    ]  # fmt: skip
    assert rows[1].largest_relative_change == pytest.approx(0.2)  # 2e-3 → 2.5e-3; retries no number
    assert rows[3].largest_relative_change is None and rows[0].largest_relative_change is None
    assert rows[3].status == ("bad", "ok") and rows[3].before == {} and not rows[3].same
    only_before = compare_manifests(manifest, {**again, "sequences": [walk]})
    assert [(r.name, r.status) for r in only_before][-1] == ("c00_s0", ("ok", "absent"))


def test_compare_cli_reads_a_committed_manifest_and_a_folder(tmp_path: Path) -> None:
    """The dress's v4 as committed (stop 32) against its stop-41 remake with the snag check:
    20 of 23 sequences the same (docs/learning.md, stop 41); the remake's folder reads as its
    manifest file does."""
    datasets = Path(__file__).parent.parent / "docs" / "datasets"
    remade = tmp_path / "dataset_dress_v4"
    remade.mkdir()
    (remade / MANIFEST_NAME).write_text((datasets / "dress_v4_stop41_manifest.json").read_text())
    runner = CliRunner()
    result = runner.invoke(main, ["dataset", "compare", str(datasets / "dress_v4_manifest.json"),
                                  str(remade)])  # fmt: skip
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[-1] == "20 of 23 sequences came out the same"
    changed = [line.split(" | ")[0] for line in lines[1:-1] if "changed" in line]
    assert changed == ["m08_s0", "m08_s1", "c00_s0"]
    capture = next(line for line in lines if line.startswith("c00_s0"))
    assert "| changed (by 5.7e-03 relative at most): retries, inside_share_mean," in capture
    manifest = json.loads((remade / MANIFEST_NAME).read_text())
    manifest["sequences"][0]["status"] = "pending"  # not simulated yet
    (remade / MANIFEST_NAME).write_text(json.dumps(manifest))
    result = runner.invoke(main, ["dataset", "compare", str(datasets / "dress_v4_manifest.json"),
                                  str(remade)])  # fmt: skip
    assert result.output.splitlines()[-1] == "19 of 23 sequences came out the same (1 not made yet)"
    result = runner.invoke(main, ["dataset", "compare", str(remade), str(remade), "--json"])
    assert all(row["same"] for row in json.loads(result.output))
    result = runner.invoke(main, ["dataset", "compare", str(datasets.parent / "judge.md"),
                                  str(remade)])  # fmt: skip
    assert result.exit_code == 1 and "not a JSON manifest" in result.output
