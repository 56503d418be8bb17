"""``usd-garment dataset make``: a seeded plan split by motion, body + simulated garment layers
with a manifest, resuming without redoing finished sequences, bad sequences marked and removed."""

from __future__ import annotations

import contextlib
import hashlib
import json
import lzma
import math
import os
import pickle
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from tests.script_calls import calls_on_base, copied_from_base, script_calls
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.methods.simulation import SimulationError
from usd_garment.motion.procedural import make_motion
from usd_garment.training import dataset as dataset_module
from usd_garment.training.dataset import (
    MANIFEST_NAME,
    DatasetConfig,
    SequenceSpec,
    make_dataset,
    plan_sequences,
    read_manifest,
    sequence_motion,
)
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.garment_read import read_garment_layer

pytest.importorskip("newton")


def test_plan_is_seeded_prefix_stable_and_split_by_motion() -> None:
    big = plan_sequences(DatasetConfig(motions=12, shapes=3, seed=4))
    small = plan_sequences(DatasetConfig(motions=5, shapes=3, seed=4))
    keys = ("name", "motion_kind", "motion_seed", "betas")
    assert [[getattr(s, k) for k in keys] for s in small] == [
        [getattr(s, k) for k in keys] for s in big[:15]
    ]
    assert plan_sequences(DatasetConfig(motions=12, shapes=3, seed=5)) != big
    assert len(big) == 36 and len({s.motion_seed for s in big}) == 12
    assert all(s.betas == [0.0] * 10 for s in big if s.shape_index == 0)
    assert all(max(map(abs, s.betas)) <= 1.0 for s in big)
    split_of = {}
    for s in big:
        assert split_of.setdefault(s.motion_index, s.split) == s.split  # one split per motion
    counts = {name: list(split_of.values()).count(name) for name in ("train", "validation", "test")}
    assert counts == {"train": 8, "validation": 2, "test": 2}


def _run(args: list[object]) -> tuple[int, str]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(result.exception, AssertionError)
    return result.exit_code, result.output


def test_make_resume_and_refuse(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "data"
    args = ["dataset", "make", "--motions", "1", "--shapes", "1", "--frames", "3", "--lod", "low",
            "--workers", "1", "-o", out]  # fmt: skip
    code, output = _run(args)
    assert code == 0, output
    manifest = read_manifest(out)
    (entry,) = manifest["sequences"]
    assert entry["status"] == "ok" and entry["split"] == "train" and entry["frames"] == 3
    assert manifest["summary"]["frames_ok"] == 3 and manifest["solver"]["substeps"] == 4
    assert manifest["splits"] == {"train": [0], "validation": [], "test": []}
    garment = out / entry["files"]["garment"]
    points, _, info = read_garment_layer(garment)
    assert points.shape == (3, manifest["vertices"], 3) and info.method == "simulation"
    assert (out / entry["files"]["body"]).is_file()
    assert entry["checks"]["nan_frames"] == 0 and entry["checks"]["max_distance_m"] < 0.15
    stamp = garment.stat().st_mtime_ns

    code, output = _run([*args, "--resume"])  # nothing left to do
    assert code == 0 and "1 of 1 sequences ok" in output
    assert garment.stat().st_mtime_ns == stamp

    code, output = _run(args)  # a dataset is there already
    assert code == 1 and "--resume" in output and "Traceback" not in output

    def fail(*args: object, **kwargs: object) -> None:
        raise SimulationError("simulation failed at motion frame 1: test")

    garment.unlink()  # a missing file makes the sequence run again
    monkeypatch.setattr(dataset_module, "dress", fail)
    code, output = _run([*args, "--resume"])
    assert code == 0 and "0 of 1 sequences ok (1 bad)" in output
    (entry,) = read_manifest(out)["sequences"]
    assert entry["status"] == "bad" and "motion frame 1" in entry["message"]
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME]  # bad files removed


def test_other_settings_are_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(
        dataset_module, "run_sequence", lambda *a: pytest.fail("nothing should run")
    )
    (tmp_path / MANIFEST_NAME).write_text(
        json.dumps({"format": 1, "config": {"garment": "dress"}, "sequences": []})
    )
    with pytest.raises(ValueError, match="other settings"):
        make_dataset(tmp_path, DatasetConfig(lod="low", motions=1, shapes=1), resume=True)


def test_only_some_splits_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    config = DatasetConfig(lod="low", motions=5, shapes=1)
    ran: list[str] = []

    def run(folder: str, config: DatasetConfig, spec: dataset_module.SequenceSpec) -> dict:
        ran.append(spec.name)
        return {**asdict(spec), "status": "bad", "message": "not simulated in this test"}

    monkeypatch.setattr(dataset_module, "run_sequence", run)
    manifest = make_dataset(tmp_path / "d", config, splits=("test",))
    test = sorted(s.name for s in plan_sequences(config) if s.split == "test")
    assert test and sorted(ran) == test
    status = {s["name"]: s["status"] for s in manifest["sequences"]}
    assert all(status[name] == ("bad" if name in test else "pending") for name in status)
    with pytest.raises(ValueError, match="unknown split"):
        make_dataset(tmp_path / "e", config, splits=("holdout",))


def test_two_workers(tmp_path: Path) -> None:
    """Two worker processes (10 s: run by default, as it checks their torch threads)."""
    config = DatasetConfig(lod="low", motions=2, shapes=1, frames=5)
    seen: list[str] = []
    manifest = make_dataset(
        tmp_path / "d", config, workers=2, on_sequence=lambda e, d, t: seen.append(e["name"])
    )
    assert sorted(seen) == ["m00_s0", "m01_s0"]
    assert manifest["summary"]["ok"] == 2 and manifest["summary"]["frames_ok"] == 10
    # One torch thread a worker: two workers at two threads each overfill two cores.
    assert [s["torch_threads"] for s in manifest["sequences"]] == [1, 1]
    assert np.isfinite(manifest["summary"]["bytes"])


def test_captures_join_the_plan_with_their_splits(tmp_path: Path) -> None:
    capture = tmp_path / "walk.usda"
    capture.write_text("#usda 1.0\n")  # only its existence matters to the plan
    config = DatasetConfig(
        motions=3, shapes=2, seed=1, captures=((str(capture), "test"),), capture_shapes=2
    )
    specs = plan_sequences(config)
    captured = [s for s in specs if s.capture]
    assert [s.name for s in captured] == ["c00_s0", "c00_s1"]
    assert {s.split for s in captured} == {"test"} and {s.motion_index for s in captured} == {3}
    assert [s.betas for s in captured] == [s.betas for s in specs[:2]]  # the same shapes
    with pytest.raises(ValueError, match="unknown split"):
        DatasetConfig(captures=((str(capture), "holdout"),))
    with pytest.raises(FileNotFoundError, match="no such capture"):
        DatasetConfig(captures=((str(tmp_path / "none.bvh"), "train"),))


def test_a_set_of_captures_alone_has_no_procedural_motion(tmp_path: Path) -> None:
    capture = tmp_path / "folded.usda"
    capture.write_text("#usda 1.0\n")
    config = DatasetConfig(
        motions=0, shapes=2, captures=((str(capture), "train"),), capture_shapes=2
    )
    specs = plan_sequences(config)
    assert [(s.name, s.split, s.motion_index) for s in specs] == [
        ("c00_s0", "train", 0),
        ("c00_s1", "train", 0),
    ]
    with pytest.raises(ValueError, match="needs captures"):
        DatasetConfig(motions=0)


def _plans(
    tmp_path: Path, motions: int, seed: int, **flag: bool
) -> tuple[list[SequenceSpec], list[SequenceSpec]]:
    """The plan of ``motions`` × 2 shapes, and the same with ``flag`` set and a test capture."""
    capture = tmp_path / "walk.usda"
    capture.write_text("#usda 1.0\n")
    plain = plan_sequences(DatasetConfig(motions=motions, shapes=2, seed=seed))
    config = DatasetConfig(
        motions=motions, shapes=2, seed=seed, captures=((str(capture), "test"),), **flag
    )
    return plain, plan_sequences(config)


def test_train_only_puts_every_procedural_motion_in_train(tmp_path: Path) -> None:
    held, extra = _plans(tmp_path, 10, 1, train_only=True)
    assert {s.split for s in extra if not s.capture} == {"train"}
    assert [s.split for s in extra if s.capture] == ["test"]
    assert {s.split for s in held} == {"train", "validation", "test"}
    keys = ("name", "motion_kind", "motion_seed", "betas")  # the same motions and shapes
    assert [[getattr(s, k) for k in keys] for s in extra[:20]] == [
        [getattr(s, k) for k in keys] for s in held
    ]


def test_kinds_choose_the_motions_and_keep_the_committed_plans() -> None:
    """``kinds`` picks the procedural motions; by default the plans of the committed datasets
    (v4, v4x: made before "hop" existed) come out as their manifests list them."""
    repo = Path(__file__).resolve().parents[1] / "docs" / "datasets"
    for name, config in (
        ("tshirt_v4", DatasetConfig(motions=10, shapes=3, seed=0)),
        ("tshirt_v4x", DatasetConfig(motions=10, shapes=3, seed=1, train_only=True)),
    ):
        listed = json.loads((repo / f"{name}_manifest.json").read_text())["sequences"]
        kinds = {e["name"]: e["motion_kind"] for e in listed if e["motion_kind"] != "capture"}
        assert {s.name: s.motion_kind for s in plan_sequences(config)} == kinds, name
    hops = plan_sequences(DatasetConfig(motions=4, shapes=2, seed=2, kinds=("hop",)))
    assert {s.motion_kind for s in hops} == {"hop"} and len({s.motion_seed for s in hops}) == 4
    assert "hop" not in {s.motion_kind for s in plan_sequences(DatasetConfig(motions=30))}
    with pytest.raises(ValueError, match="unknown motion kinds"):
        DatasetConfig(kinds=("hop", "cartwheel"))


def test_a_captured_body_layer_is_simulated_whole(tmp_path: Path, body_model: BodyModel) -> None:
    capture = tmp_path / "capture.usda"
    write_body_layer(capture, make_motion("walk", 8, 60.0, seed=2, body=body_model), body_model)
    out = tmp_path / "data"
    code, output = _run(["dataset", "make", "--motions", "1", "--shapes", "1", "--frames", "2",
                         "--lod", "low", "--workers", "1", "--capture", f"{capture}:validation",
                         "-o", out])  # fmt: skip
    assert code == 0, output
    entries = {e["name"]: e for e in read_manifest(out)["sequences"]}
    assert sorted(entries) == ["c00_s0", "m00_s0"]
    entry = entries["c00_s0"]
    assert entry["status"] == "ok" and entry["split"] == "validation"
    assert entry["frames"] == 4  # 8 frames at 60 fps, played whole at 30 fps
    points = read_garment_layer(out / entry["files"]["garment"])[0]
    assert points.shape[0] == 4
    code, output = _run(["dataset", "make", "--capture", capture, "-o", tmp_path / "x"])
    assert code != 0 and "FILE:SPLIT" in output


def test_a_sequence_that_errors_is_recorded_and_the_others_go_on(tmp_path: Path) -> None:
    broken = tmp_path / "broken.usda"
    broken.write_text("#usda 1.0\n(\n")  # not a USD layer: reading it raises
    out = tmp_path / "data"
    args = ["dataset", "make", "--motions", "1", "--shapes", "1", "--frames", "2", "--lod", "low",
            "--workers", "1", "--capture", f"{broken}:train", "-o", out]  # fmt: skip
    code, output = _run(args)
    assert code == 1 and "sequence c00_s0 failed (--resume retries)" in output, output
    entries = {e["name"]: e for e in read_manifest(out)["sequences"]}
    assert entries["m00_s0"]["status"] == "ok"
    assert entries["c00_s0"]["status"] == "error" and entries["c00_s0"]["message"]
    assert read_manifest(out)["summary"]["errors"] == 1
    assert sorted(p.name for p in out.iterdir() if p.name.startswith("c00")) == []


def test_a_worker_sends_back_an_error_it_could_not_pickle(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    class Unpicklable(RuntimeError):
        def __reduce__(self) -> Any:
            raise TypeError("not picklable")  # as pxr.Tf.Error

    def fail(*_: object) -> dict[str, Any]:
        raise Unpicklable("a USD error")

    monkeypatch.setattr(dataset_module, "run_sequence", fail)
    spec = plan_sequences(DatasetConfig(motions=1, shapes=1))[0]
    entry = dataset_module._run_task((str(tmp_path), DatasetConfig(), spec))
    assert pickle.loads(pickle.dumps(entry)) == entry
    assert entry["status"] == "error" and "a USD error" in entry["message"]


def _children(pid: int) -> set[int]:
    """Processes whose parent is ``pid`` (Linux /proc)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(stat.parent.name))
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="needs Linux /proc")
def test_kill_ends_the_dataset_workers_with_the_command(tmp_path: Path) -> None:
    """SIGTERM to ``dataset make`` terminates its pool: no worker goes on writing the folder."""
    out = tmp_path / "data"
    command = [sys.executable, "-c", "from usd_garment.cli.main import main; main()",
               "dataset", "make", "--motions", "2", "--shapes", "1", "--frames", "40",
               "--lod", "low", "--workers", "2", "-o", str(out)]  # fmt: skip
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: set[int] = set()
    try:
        deadline = time.monotonic() + 120.0  # the pool's two workers (and resource tracker)
        while time.monotonic() < deadline and len(_children(process.pid)) < 2:
            time.sleep(0.2)
        workers = _children(process.pid)
        assert workers, "the pool did not start"
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 128 + signal.SIGTERM
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and any(Path(f"/proc/{w}").exists() for w in workers):
            time.sleep(0.2)
        assert not any(Path(f"/proc/{w}/stat").is_file() for w in workers)
    finally:
        process.kill()
        for worker in workers:  # left behind only if the test failed
            with contextlib.suppress(ProcessLookupError):
                os.kill(worker, signal.SIGKILL)


def test_a_bvh_capture_plays_whole_at_the_dataset_rate(
    body_model: BodyModel, tmp_path: Path
) -> None:
    """A BVH capture, here xz-compressed as the captures of ``examples/mocap``."""
    source = Path(__file__).parents[2] / "shared" / "mocap" / "cmu_131_01.bvh"
    if not source.is_file():
        pytest.skip("the shared CMU clips are not beside the project")
    clip = tmp_path / "cmu_131_01.bvh.xz"
    clip.write_bytes(lzma.compress(source.read_bytes()))
    config = DatasetConfig(shapes=2, captures=((str(clip), "train"),), capture_shapes=2)
    spec = [s for s in plan_sequences(config) if s.capture][1]
    motion = sequence_motion(config, spec, body_model)
    assert motion.fps == 30.0 and motion.num_frames == 249  # 995 frames at 120 fps
    np.testing.assert_array_equal(motion.betas, np.asarray(spec.betas, dtype=np.float32))
    np.testing.assert_array_equal(motion.time_codes, np.arange(249))


def test_collars_reach_the_capture_reader(
    body_model: BodyModel, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``collars`` goes to the capture reader (``import-bvh --collars``, tested in
    ``test_bvh.py``) and into the manifest; an unknown mode is refused."""
    clip = tmp_path / "clip.bvh"
    clip.write_text("HIERARCHY\n")
    asked: list[str] = []

    def reader(path: Path, body: BodyModel, betas: np.ndarray, collars: str) -> Any:
        asked.append(collars)
        return make_motion("walk", 8, 30.0, 0, betas, body)

    monkeypatch.setattr(dataset_module, "read_motion_file", reader)
    config = DatasetConfig(motions=0, shapes=1, captures=((str(clip), "train"),), collars="rest")
    assert sequence_motion(config, plan_sequences(config)[0], body_model).num_frames == 8
    assert asked == ["rest"] and config.to_json()["collars"] == "rest"
    with pytest.raises(ValueError, match="unknown collars"):
        DatasetConfig(collars="up")


def test_shape_per_motion_gives_each_motion_its_own_shapes(tmp_path: Path) -> None:
    """``shape_per_motion``: N motions × M shapes bring N × M random shapes (none is β = 0),
    the motions are those of the shared-shape plan, a plan of more motions starts with that of
    fewer, and captures keep the shared shapes."""
    shared, own = _plans(tmp_path, 4, 5, shape_per_motion=True)
    procedural = [s for s in own if not s.capture]
    betas = {tuple(s.betas) for s in procedural}
    assert len(betas) == 8 and all(any(b != 0.0 for b in shape) for shape in betas)
    keys = ("name", "motion_kind", "motion_seed", "split")
    assert [[getattr(s, k) for k in keys] for s in procedural] == [
        [getattr(s, k) for k in keys] for s in shared
    ]
    more = plan_sequences(DatasetConfig(motions=6, shapes=2, seed=5, shape_per_motion=True))
    assert [s.betas for s in more[:8]] == [s.betas for s in procedural]
    assert [s.betas for s in own if s.capture] == [[0.0] * len(shared[0].betas)]


#: Each option a manifest may lack, with the value that sets made before it had (if not today's
#: default).
OPTIONS_ADDED = [("train_only", {}), ("kinds", {}), ("shape_per_motion", {}),
                 ("collars", {"collars": "aimed"})]  # fmt: skip


@pytest.mark.parametrize("option,then", OPTIONS_ADDED)
def test_a_manifest_made_before_an_option_existed_resumes_as_it_was(
    option: str, then: dict[str, Any]
) -> None:
    """A manifest written before ``option`` existed lacks it, and ``_fixed`` gives it the value
    every set had then (``then``'s, else today's default): the dataset resumes as it was (the
    collars were aimed until the setting came, ``rest`` is the default since stop 59)."""
    made_then = DatasetConfig(**then).to_json()
    before = {k: v for k, v in made_then.items() if k != option}
    assert dataset_module._fixed(before) == dataset_module._fixed(made_then)


#: The committed manifests of the training sets.
MANIFESTS = Path(__file__).parent.parent / "docs" / "datasets"


def _sets_made_as_committed(calls: list[list[str]], garment: str, suffix: str) -> list[str]:
    """The names of the sets that data.sh's ``calls`` make, each checked against the settings
    its committed manifest ``docs/datasets/GARMENT_NAME{suffix}_manifest.json`` records (its
    ``dataset make`` lines read by the command's own parser; the captures by :func:`_tails`)."""
    from usd_garment.cli.dataset import _capture, make

    made = []
    for args in calls:
        if args[:2] != ["dataset", "make"]:
            continue
        params = make.make_context("make", args[2:]).params
        name = params["output"].name.removeprefix(f"dataset_{garment}_")
        made.append(name)
        path = MANIFESTS / f"{garment}_{name}{suffix}_manifest.json"
        config = json.loads(path.read_text())["config"]
        keys = ("garment", "motions", "shapes", "frames", "seed", "shape_sigma", "train_only",
                "open_shoulders", "capture_shapes", "lod", "substeps", "iterations")  # fmt: skip
        for key in keys:
            assert params[key] == config[key], (name, key)
        assert params["shape_per_motion"] == config.get("shape_per_motion", False), name
        assert params["collars"] == config.get("collars", "aimed"), name
        captures = [list(_capture(text)) for text in params["captures"]]
        assert _tails(captures) == _tails(config["captures"]), name
    return made


def _projections(calls: list[list[str]]) -> list[tuple[str, str]]:
    """The ``(--manifest, -o)`` of each ``project`` call in a script's ``calls``."""
    return [
        (a[a.index("--manifest") + 1], a[a.index("-o") + 1]) for a in calls if a[0] == "project"
    ]


def _tails(captures: list[list[str]]) -> list[tuple[tuple[str, ...], str]]:
    """Captures ``[path, split]`` with each path cut to its last three parts (a manifest made
    with an absolute OUT records where that machine kept the imports)."""
    return [(Path(path).parts[-3:], split) for path, split in captures]


@pytest.mark.parametrize("garment", ["tshirt", "dress"])
def test_the_data_script_makes_the_committed_sets(garment: str, tmp_path: Path) -> None:
    """``COLLARS=aimed examples/train/data.sh GARMENT`` imports the captures and makes each set
    with the settings its committed manifest (``docs/datasets/GARMENT_NAME_manifest.json``: the
    T-shirt's version 7 and the dress's version 9 data) records (its ``dataset make`` lines read
    by the command's own parser), then projects the sets onto the two canonical sets."""
    calls = script_calls("data.sh", garment, tmp_path=tmp_path, env={"COLLARS": "aimed"})
    made = _sets_made_as_committed(calls, garment, "")
    extra = ["v5s"] if garment == "tshirt" else ["v5s", "v6s"]
    assert made == ["v4", "v4x", "cmu4", *extra]
    cmu4 = json.loads((MANIFESTS / f"{garment}_cmu4_manifest.json").read_text())
    imported = [a[a.index("-o") + 1] for a in calls if a[0] == "import-bvh"]
    assert imported == [path for path, _ in cmu4["config"]["captures"]]
    projected = _projections(calls)
    last = "v4cs" if garment == "tshirt" else "v4css"
    first = [(f"scratch/dataset_{garment}_{n}", f"scratch/canonical_{garment}_v4c.npz")
             for n in made[:3]]  # fmt: skip
    then = [(f"scratch/dataset_{garment}_{n}", f"scratch/canonical_{garment}_{last}.npz")
            for n in extra]  # fmt: skip
    assert projected == first + then


@pytest.mark.parametrize(
    ("garment", "suffix", "sets"),
    [("tshirt", "_rest_stop55", ["v4", "v4x", "cmu4", "v5s"]),
     ("dress", "_rest_stop59", ["v4", "v4x", "cmu4", "v5s", "v6s"])],
)  # fmt: skip
def test_the_data_script_takes_the_collars(
    garment: str, suffix: str, sets: list[str], tmp_path: Path
) -> None:
    """``bash examples/train/data.sh GARMENT``: by default the captures imported and every set
    made with ``--collars rest``, as the T-shirt's version 8 sets of stop 55 and the dress's
    version 10 sets of stop 59 were (``docs/datasets/GARMENT_NAME{suffix}_manifest.json``)."""
    calls = script_calls("data.sh", garment, tmp_path=tmp_path)
    kinds = [a for a in calls if a[0] == "import-bvh" or a[:2] == ["dataset", "make"]]
    assert len(kinds) == 4 + len(sets)
    assert all(a[a.index("--collars") + 1] == "rest" for a in kinds)
    assert _sets_made_as_committed(calls, garment, suffix) == sets


def test_the_cap35_data_script_makes_stop_81s_set(tmp_path: Path) -> None:
    """``examples/train/data_cap35.sh tshirt OUT BASE`` imports the 35 captures of
    ``examples/mocap/cmu35`` whole (the importer leaves the T-pose out: 5,321 frames at 30 fps,
    as the mocap README says), each the file its README lists by SHA-256, makes the train-only
    set cap35 of them with cmu4's settings (its committed rest manifest's), and projects it onto
    copies of BASE's two canonical sets."""
    from usd_garment.cli.dataset import make

    calls = calls_on_base("data_cap35.sh", "scratch/c35", tmp_path)
    imports = [a for a in calls if a[0] == "import-bvh"]
    assert all(a[a.index("--collars") + 1] == "rest" and "--frames" not in a for a in imports)
    readme = (MANIFESTS.parent.parent / "examples" / "mocap" / "README.md").read_text()
    listed = {}  # name → (SHA-256, frames in the file)
    for line in readme.split("## Thirty-five captures")[1].splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1].endswith(".bvh"):
            listed[parts[1]] = (parts[0], int(parts[2]))
    assert len(listed) == 35
    seen, frames = [], 0
    for a in imports:
        text = lzma.decompress((tmp_path / "work" / a[1]).read_bytes())
        name = Path(a[1]).name.removeprefix("cmu_").removesuffix(".xz")
        count = int(text.split(b"Frames:", 1)[1].split(maxsplit=1)[0])
        assert listed[name] == (hashlib.sha256(text).hexdigest(), count), name
        seen.append(name)
        frames += math.ceil((count - 1) / 4)  # frames 1 to the last, 120 fps to 30
    assert sorted(seen) == sorted(listed) and frames == 5321
    (make_args,) = [a for a in calls if a[:2] == ["dataset", "make"]]
    params = make.make_context("make", make_args[2:]).params
    cmu4 = json.loads((MANIFESTS / "tshirt_cmu4_rest_stop55_manifest.json").read_text())
    keys = ("garment", "motions", "shapes", "frames", "seed", "shape_sigma", "train_only",
            "open_shoulders", "capture_shapes", "lod", "substeps", "iterations")  # fmt: skip
    for key in (*keys, "collars"):
        assert params[key] == cmu4["config"][key], key
    assert params["output"].name == "dataset_tshirt_cap35"
    assert params["captures"] == tuple(f"{a[a.index('-o') + 1]}:train" for a in imports)
    assert _projections(calls) == [
        ("scratch/c35/dataset_tshirt_cap35", f"scratch/c35/canonical_tshirt_{n}.npz")
        for n in ("v4c", "v4cs")
    ]
    assert copied_from_base(tmp_path, "scratch/c35")


def test_the_arms_data_script_makes_the_committed_sets(tmp_path: Path) -> None:
    """``examples/train/data_arms.sh tshirt OUT BASE`` imports data.sh's cmu4 clips (the same
    frames and names) and CMU 131_01 with the arms as captured (``--arm-clearance 0``, rest
    collars), makes the sets arms5 and arms4b with the settings their committed manifests
    (``docs/datasets/tshirt_NAME_stop64_manifest.json``) record, and projects arms5 onto a copy
    of BASE's v4cs, then arms4b onto a copy of that."""
    calls = calls_on_base("data_arms.sh", "scratch/s64", tmp_path, ("v4cs",))
    imports = [a for a in calls if a[0] == "import-bvh"]
    assert all(a[a.index("--arm-clearance") + 1] == "0" for a in imports)
    assert all(a[a.index("--collars") + 1] == "rest" for a in imports)
    (tmp_path / "data").mkdir()
    cmu4 = [a for a in script_calls("data.sh", "tshirt", tmp_path=tmp_path / "data")
            if a[0] == "import-bvh"]  # fmt: skip

    def clip(args: list[str]) -> tuple[str, str, str]:  # the BVH, its frames, the layer's name
        return args[1], args[args.index("--frames") + 1], Path(args[args.index("-o") + 1]).name

    assert [clip(a) for a in imports[:4]] == [clip(a) for a in cmu4]
    assert Path(imports[4][1]).name == "cmu_131_01.bvh" and "--frames" not in imports[4]
    assert _sets_made_as_committed(calls, "tshirt", "_stop64") == ["arms5", "arms4b"]
    projected = _projections(calls)
    assert projected == [
        ("scratch/s64/dataset_tshirt_arms5", "scratch/s64/canonical_tshirt_v4cs_arms.npz"),
        ("scratch/s64/dataset_tshirt_arms4b", "scratch/s64/canonical_tshirt_v4cs_arms3.npz"),
    ]
    for name in ("arms", "arms3"):
        copy = tmp_path / "work" / "scratch" / "s64" / f"canonical_tshirt_v4cs_{name}.npz"
        assert copy.read_text() == "v4cs"  # BASE's file, copied before the projections
