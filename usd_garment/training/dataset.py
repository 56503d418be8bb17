"""Training data: a garment simulated on seeded procedural motions and real captures × random body
shapes, one SMPL body layer and one simulated garment layer per (motion, shape) pair, listed in a
JSON manifest.

Motions rotate through the config's kinds (``DATASET_KINDS`` by default) in a seeded order, each
with its own seed, arms free to hang against the trunk unless ``open_shoulders``; captures (BVH
files, or USD body layers such as ``import-amass`` writes) follow, each played whole at the
dataset's frame rate with the split it was given. Shape 0 is the mean body (β = 0), the others come
from ``random_betas``. The split into train / validation / test is by motion, so test motions are
never seen in training.
Sequences run one per worker process (Warp runs CPU kernels on one thread); the manifest is
rewritten after each one, so an interrupted run resumes where it stopped. A sequence that fails
its simulation checks is marked "bad" and its files are removed.
"""

from __future__ import annotations

import json
import multiprocessing
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment.atomic import atomic_output
from usd_garment.body.io import load_body_model
from usd_garment.body.joints import NUM_BETAS
from usd_garment.body.model import BodyModel
from usd_garment.dress import dress
from usd_garment.garment.library import load_template
from usd_garment.garment.template import GARMENT_NAMES, LODS
from usd_garment.methods.simulation import SimulationError, SimulationMethod
from usd_garment.motion.bvh import COLLAR_MODES, DEFAULT_COLLARS
from usd_garment.motion.motion_file import read_motion_file
from usd_garment.motion.procedural import MOTION_KINDS, make_motion, random_betas
from usd_garment.motion.resample import resample_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.sim.cloth import ITERATIONS, SUBSTEPS
from usd_garment.sim.material import ClothMaterial
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.errors import UsdInputError
from usd_garment.usd.garment_read import read_garment_layer

MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = 1
#: The splits of a dataset, by motion.
SPLITS = ("train", "validation", "test")
#: The motion kinds of a dataset unless its config names others: every kind of
#: ``MOTION_KINDS`` that existed when datasets v3 and v4 were made, in that order (a kind added
#: later, such as "hop", joins only when asked for, so those datasets' plans stay as they were).
DATASET_KINDS = ("walk", "run", "arm_raise", "arm_swing", "torso_twist", "torso_bend", "squat",
                 "jumping_jacks", "random_smooth")  # fmt: skip
#: Shares of the motions in the validation and test splits (the rest is train).
VALIDATION_SHARE = TEST_SHARE = 0.15
#: Called after each sequence with its manifest entry, sequences done and sequences to do.
SequenceProgress = Callable[[dict[str, Any], int, int], None]


@dataclass(frozen=True)
class DatasetConfig:
    """What a dataset is made of; equal configs make equal datasets.

    Attributes:
        garment: garment name; lod: its level of detail.
        motions: number of motions N (0 for a set of captures alone); shapes: number of body
            shapes M (N × M sequences).
        frames: frames per sequence at ``fps``.
        seed: seed of the motion kinds and seeds, the shapes and the split.
        substeps, iterations: solver steps per frame and iterations per step.
        material: the fabric.
        shape_sigma: ``random_betas``'s clip (±σ).
        open_shoulders: procedural motions open the shoulders to keep the arms clear of the
            torso (off: arms hang against the trunk as in capture).
        captures: real motions, ``(path, split)`` pairs: a BVH file (``.bvh``, ``.bvh.xz``,
            ``.bvh.gz``) or an AMC one (its ASF beside it), an AMASS ``.npz`` or a USD body
            layer, simulated on the first ``capture_shapes`` shapes, whole, resampled to
            ``fps``.
        capture_shapes: how many of the shapes each capture is simulated on.
        train_only: every procedural motion goes to the train split (more training data for a
            model whose held-out motions come from another dataset); captures keep theirs.
        kinds: the procedural motion kinds the motions rotate through (``MOTION_KINDS``).
        shape_per_motion: each procedural motion gets ``shapes`` body shapes of its own, all
            drawn at random (none is β = 0): N motions bring N × M shapes, for a model that
            must hold on shapes it never saw. Captures keep the shared shapes (β = 0 first).
        collars: how BVH captures' collar bones are retargeted (``COLLAR_MODES``, as
            ``import-bvh --collars``).
    """

    garment: str = "tshirt"
    lod: str = "high"
    motions: int = 12
    shapes: int = 3
    frames: int = 90
    fps: float = 30.0
    seed: int = 0
    substeps: int = SUBSTEPS
    iterations: int = ITERATIONS
    material: ClothMaterial = field(default_factory=ClothMaterial)
    shape_sigma: float = 1.0
    open_shoulders: bool = False
    captures: tuple[tuple[str, str], ...] = ()
    capture_shapes: int = 1
    train_only: bool = False
    kinds: tuple[str, ...] = DATASET_KINDS
    shape_per_motion: bool = False
    collars: str = DEFAULT_COLLARS

    def __post_init__(self) -> None:
        if self.garment not in GARMENT_NAMES:
            raise ValueError(f"unknown garment '{self.garment}' ({', '.join(GARMENT_NAMES)})")
        if self.lod not in LODS:
            raise ValueError(f"unknown level of detail '{self.lod}' ({', '.join(LODS)})")
        if self.motions < 0 or self.shapes < 1 or self.frames < 1 or not self.fps > 0:
            raise ValueError("motions must be >= 0, shapes and frames >= 1 and fps > 0")
        if self.motions == 0 and not self.captures:
            raise ValueError("a dataset of no procedural motions needs captures")
        if not self.shape_sigma > 0:
            raise ValueError("shape_sigma must be > 0")
        unknown = [k for k in self.kinds if k not in MOTION_KINDS]
        if unknown or not self.kinds:
            raise ValueError(f"unknown motion kinds {unknown} ({', '.join(MOTION_KINDS)})")
        if self.collars not in COLLAR_MODES:
            raise ValueError(f"unknown collars '{self.collars}' ({', '.join(COLLAR_MODES)})")
        if not 1 <= self.capture_shapes <= self.shapes:
            raise ValueError(f"capture_shapes must be in [1, {self.shapes}]")
        for path, split in self.captures:
            if split not in SPLITS:
                raise ValueError(f"{path}: unknown split '{split}' ({', '.join(SPLITS)})")
            if not Path(path).is_file():
                raise FileNotFoundError(f"{path}: no such capture file")

    def to_json(self) -> dict[str, Any]:
        values = asdict(self)
        values["material"] = self.material.to_dict()
        values["captures"] = [list(c) for c in self.captures]
        values["kinds"] = list(self.kinds)
        return values

    def method(self) -> SimulationMethod:
        """The configured simulation method."""
        return SimulationMethod(self.substeps, self.iterations, self.material)


@dataclass(frozen=True)
class SequenceSpec:
    """One (motion, shape) pair of a dataset.

    Attributes:
        name: e.g. ``m03_s1`` (``c00_s0`` for a capture); the files are ``{name}_body.usdc``
            and ``{name}_{garment}.usdc``.
        motion_index, motion_kind, motion_seed: the motion and its ``make_motion`` arguments
            (kind "capture" and seed 0 for a capture).
        shape_index, betas: the body shape (``(10,)`` list).
        split: "train", "validation" or "test" (by motion).
        capture: the capture file, empty for a procedural motion.
    """

    name: str
    motion_index: int
    motion_kind: str
    motion_seed: int
    shape_index: int
    betas: list[float]
    split: str
    capture: str = ""


def body_file(spec: SequenceSpec) -> str:
    return f"{spec.name}_body.usdc"


def garment_file(spec: SequenceSpec, garment: str) -> str:
    return f"{spec.name}_{garment}.usdc"


def motion_splits(motions: int, seed: int) -> list[str]:
    """Split of each motion index: a seeded shuffle, then test, validation, train (at least one
    test and one validation motion from 3 motions on)."""
    order = np.random.default_rng([seed, 2]).permutation(motions)
    n_test = max(1, round(TEST_SHARE * motions)) if motions >= 3 else 0
    n_val = max(1, round(VALIDATION_SHARE * motions)) if motions >= 3 else 0
    splits = [""] * motions
    for rank, index in enumerate(order.tolist()):
        splits[index] = (
            "test" if rank < n_test else "validation" if rank < n_test + n_val else "train"
        )
    return splits


def plan_sequences(config: DatasetConfig) -> list[SequenceSpec]:
    """The dataset's sequences, motion-major. Motion i has kind ``order[i mod K]`` of a seeded
    permutation of the config's K kinds and its own seed; shape 0 is β = 0 unless each motion
    draws its own shapes (``shape_per_motion``). The plan of N motions × M shapes starts with
    that of fewer motions or shapes made with the same seed."""
    kinds = list(config.kinds)
    order = np.random.default_rng([config.seed, 0]).permutation(len(kinds))
    shapes = [np.zeros(NUM_BETAS, dtype=np.float32)] + [
        random_betas(np.random.default_rng([config.seed, 1, j]), config.shape_sigma)
        for j in range(1, config.shapes)
    ]
    splits = (
        ["train"] * config.motions
        if config.train_only
        else motion_splits(config.motions, config.seed)
    )
    specs = []
    for i in range(config.motions):
        motion_seed = int(np.random.SeedSequence([config.seed, 3, i]).generate_state(1)[0])
        own = (
            [
                random_betas(np.random.default_rng([config.seed, 4, i, j]), config.shape_sigma)
                for j in range(config.shapes)
            ]
            if config.shape_per_motion
            else shapes
        )
        for j, betas in enumerate(own):
            specs.append(
                SequenceSpec(
                    name=f"m{i:02d}_s{j}",
                    motion_index=i,
                    motion_kind=kinds[int(order[i % len(kinds)])],
                    motion_seed=motion_seed,
                    shape_index=j,
                    betas=[round(float(b), 6) for b in betas],
                    split=splits[i],
                )
            )
    for k, (path, split) in enumerate(config.captures):
        for j, betas in enumerate(shapes[: config.capture_shapes]):
            specs.append(
                SequenceSpec(
                    name=f"c{k:02d}_s{j}",
                    motion_index=config.motions + k,
                    motion_kind="capture",
                    motion_seed=0,
                    shape_index=j,
                    betas=[round(float(b), 6) for b in betas],
                    split=split,
                    capture=path,
                )
            )
    return specs


def sequence_motion(config: DatasetConfig, spec: SequenceSpec, body: BodyModel) -> SmplMotion:
    """The body motion of ``spec``: the procedural motion, or the capture played whole at the
    dataset's frame rate on the spec's body shape, time codes from 0."""
    betas = np.asarray(spec.betas, dtype=np.float32)
    if not spec.capture:
        return make_motion(
            spec.motion_kind, config.frames, config.fps, spec.motion_seed, betas, body,
            config.open_shoulders,
        )  # fmt: skip
    captured = read_motion_file(spec.capture, body, betas, collars=config.collars)
    motion = resample_motion(captured, config.fps)
    motion.time_codes = np.arange(motion.num_frames, dtype=np.float64)
    return motion


def run_sequence(folder: str, config: DatasetConfig, spec: SequenceSpec) -> dict[str, Any]:
    """Make one sequence's body layer and simulated garment layer in ``folder``.

    Returns:
        Its manifest entry; on a failed simulation status "bad" and no files left behind.

    Raises:
        Whatever reading the capture, writing the layers or the simulator raise besides a
        failed simulation (``make_dataset`` records those as status "error").
    """
    started = time.perf_counter()
    out = Path(folder)
    body = load_body_model(None)
    motion = sequence_motion(config, spec, body)
    body_path, garment_path = out / body_file(spec), out / garment_file(spec, config.garment)
    write_body_layer(body_path, motion, body)
    method = config.method()
    entry: dict[str, Any] = {**asdict(spec), "frames": motion.num_frames}
    try:
        dress(body_path, garment_path, garment=config.garment, method=method, lod=config.lod)
    except SimulationError as exc:
        body_path.unlink(missing_ok=True)
        garment_path.unlink(missing_ok=True)
        entry.update(status="bad", message=str(exc), files={})
    else:
        entry.update(
            status="ok", message="",
            files={"body": body_path.name, "garment": garment_path.name},
        )  # fmt: skip
    summary = method.settings
    entry["checks"] = {
        key: summary.get(key)
        for key in (
            "seconds_per_frame", "retries", "nan_frames", "bad_frames", "lead_in_bad_frames",
            "inside_share_mean", "inside_share_max", "inside_forced_share_mean",
            "inside_forced_share_max", "inside_elsewhere_share_mean",
            "inside_elsewhere_share_max", "penetrating_share_max", "max_distance_m",
            "stretch_p99_max", "stretch_max", "projected_share_mean", "projected_share_max",
        )
    }  # fmt: skip
    entry["seconds"] = time.perf_counter() - started
    entry["torch_threads"] = torch.get_num_threads()  # the seconds' context (make_dataset)
    return entry


def _fixed(config: dict[str, Any]) -> dict[str, Any]:
    """A config without the motion, shape and capture lists: the plan of more motions, shapes or
    captures starts with that of fewer, so a dataset can be resumed with more (a manifest made
    before ``train_only``, ``kinds``, ``shape_per_motion`` or ``collars`` existed had none: it
    has the defaults)."""
    defaults = {
        "train_only": False, "kinds": list(DATASET_KINDS), "shape_per_motion": False,
        "collars": "aimed",  # what every manifest before the setting was made with
    }  # fmt: skip
    return {
        k: v
        for k, v in {**defaults, **config}.items()
        if k not in ("motions", "shapes", "captures", "capture_shapes")
    }


def _run_task(task: tuple[str, DatasetConfig, SequenceSpec]) -> dict[str, Any]:
    """``run_sequence``, with any other error than a failed simulation recorded as the entry's
    status "error" and its message: the other sequences go on, ``resume`` tries it again, and
    a worker never has to send an exception back (USD's are not picklable: one ended a whole
    pool, and the sequences simulating beside it, with an error that did not say what failed)."""
    folder, config, spec = task
    try:
        return run_sequence(folder, config, spec)
    except Exception as exc:  # recorded in the manifest, reported by the CLI
        for name in (body_file(spec), garment_file(spec, config.garment)):
            (Path(folder) / name).unlink(missing_ok=True)
        message = " ".join(f"{type(exc).__name__}: {exc}".split())
        return {**asdict(spec), "status": "error", "message": message, "files": {}}


def sequence_is_done(folder: Path, config: DatasetConfig, entry: dict[str, Any] | None) -> bool:
    """Whether a manifest entry is finished: "bad", or "ok" with both files present and a
    garment layer of the expected frames and vertices."""
    if entry is None or entry.get("status") not in ("ok", "bad"):
        return False
    if entry["status"] == "bad":
        return True
    files = entry.get("files", {})
    paths = [folder / files.get("body", ""), folder / files.get("garment", "")]
    if not all(p.is_file() for p in paths):
        return False
    try:
        points = read_garment_layer(paths[1])[0]
    except UsdInputError:
        return False
    vertices = len(load_template(config.garment, config.lod).vertices)
    return points.shape[:2] == (entry.get("frames"), vertices)


def read_manifest(folder: str | Path) -> dict[str, Any]:
    """The manifest of the dataset in ``folder``, or the manifest file ``folder`` (a copy, as
    those committed in ``docs/datasets``).

    Raises:
        FileNotFoundError: no manifest; ValueError: not a manifest.
    """
    path = Path(folder)
    if not path.is_file():
        path = path / MANIFEST_NAME
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no dataset manifest")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a JSON manifest ({exc.msg})") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != MANIFEST_FORMAT:
        raise ValueError(f"{path}: not a dataset manifest of format {MANIFEST_FORMAT}")
    return manifest


def check_splits(splits: Sequence[str]) -> None:
    """Raise ``ValueError`` unless ``splits`` names at least one split, all of them known."""
    unknown = [s for s in splits if s not in SPLITS]
    if unknown or not splits:
        raise ValueError(f"unknown split '{unknown[0] if unknown else ''}' ({', '.join(SPLITS)})")


@dataclass(frozen=True)
class DatasetLayers:
    """The ok sequences of a dataset, as layer paths (for ``usd-garment project``).

    Attributes:
        garment, lod: the simulated garment template.
        names: sequence names (e.g. ``m03_s1``), by split (in the order asked) then name.
        splits: the split of each sequence.
        bodies, garments: the body layer and the simulated garment layer of each sequence.
    """

    garment: str
    lod: str
    names: list[str]
    splits: list[str]
    bodies: list[Path]
    garments: list[Path]


def dataset_layers(folder: str | Path, splits: Sequence[str] = SPLITS) -> DatasetLayers:
    """The ok sequences in ``splits`` of the dataset in ``folder`` (or of the manifest file).

    Raises:
        FileNotFoundError: no manifest; ValueError: not a manifest, an unknown split, or no ok
            sequence in those splits.
    """
    folder = Path(folder)
    if folder.name == MANIFEST_NAME and folder.is_file():
        folder = folder.parent
    check_splits(splits)
    manifest = read_manifest(folder)
    chosen = [q for q in manifest["sequences"] if q["status"] == "ok" and q["split"] in splits]
    if not chosen:
        raise ValueError(f"{folder}: no ok sequence in the splits {', '.join(splits)}")
    chosen.sort(key=lambda q: (list(splits).index(q["split"]), q["name"]))
    return DatasetLayers(
        garment=manifest["garment"],
        lod=manifest["lod"],
        names=[q["name"] for q in chosen],
        splits=[q["split"] for q in chosen],
        bodies=[folder / q["files"]["body"] for q in chosen],
        garments=[folder / q["files"]["garment"] for q in chosen],
    )


def _write_manifest(folder: Path, manifest: dict[str, Any]) -> None:
    ok = [s for s in manifest["sequences"] if s["status"] == "ok"]
    manifest["summary"] = {
        "sequences": len(manifest["sequences"]),
        "ok": len(ok),
        "bad": sum(s["status"] == "bad" for s in manifest["sequences"]),
        "errors": sum(s["status"] == "error" for s in manifest["sequences"]),
        "frames_ok": sum(s["frames"] for s in ok),
        "bytes": sum((folder / f).stat().st_size for s in ok for f in s["files"].values()),
    }
    with atomic_output(folder / MANIFEST_NAME) as tmp:
        tmp.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")


def make_dataset(
    folder: str | Path,
    config: DatasetConfig,
    *,
    workers: int = 1,
    resume: bool = False,
    splits: Sequence[str] = SPLITS,
    on_sequence: SequenceProgress | None = None,
) -> dict[str, Any]:
    """Make (or, with ``resume``, finish) the dataset ``config`` in ``folder``.

    Args:
        folder: output folder (created; its parent must exist).
        config: what to make.
        workers: processes simulating one sequence each at a time (spawned, one torch
            thread each: with torch's default two threads each, two workers on two cores
            simulated at 0.75 s a frame against 0.47); 1 runs in this process.
        resume: keep the finished sequences of an existing manifest with the same config (the
            motion and shape counts may grow; splits are reassigned).
        splits: simulate only the sequences of these splits (e.g. ``("test",)`` to rebuild the
            held-out sequences for a benchmark); the others stay "pending" in the manifest for a
            later ``resume``.
        on_sequence: called after each sequence made (see ``SequenceProgress``).

    Returns:
        The manifest (also written to ``folder/manifest.json``).

    Raises:
        ValueError: a manifest already there without ``resume``, made with another config, or
            an unknown split.
        FileNotFoundError: the parent folder does not exist.
    """
    folder = Path(folder)
    if workers < 1:
        raise ValueError("workers must be >= 1")
    check_splits(splits)
    if not folder.parent.is_dir():
        raise FileNotFoundError(f"{folder.parent}: folder does not exist")
    specs = plan_sequences(config)
    previous: dict[str, dict[str, Any]] = {}
    if (folder / MANIFEST_NAME).is_file():
        if not resume:
            raise ValueError(f"{folder} already holds a dataset: pass --resume or another folder")
        old = read_manifest(folder)
        if _fixed(old.get("config", {})) != _fixed(config.to_json()):
            raise ValueError(f"{folder}: the dataset there was made with other settings")
        previous = {s["name"]: s for s in old["sequences"]}
    folder.mkdir(exist_ok=True)
    method = config.method()
    solver = {k: v for k, v in method.settings.items() if k != "material"}
    entries = {}
    for spec in specs:
        entry = previous.get(spec.name)
        same = entry is not None and all(
            entry.get(k) == v for k, v in asdict(spec).items() if k != "split"
        )
        if not same or not sequence_is_done(folder, config, entry):
            entry = {**asdict(spec), "status": "pending"}
        entries[spec.name] = {**entry, "split": spec.split}
    manifest: dict[str, Any] = {
        "format": MANIFEST_FORMAT,
        "config": config.to_json(),
        "garment": config.garment,
        "lod": config.lod,
        "vertices": len(load_template(config.garment, config.lod).vertices),
        "body_model": load_body_model(None).name,
        "seed": config.seed,
        "material": config.material.to_dict(),
        "solver": solver,
        "splits": {
            split: sorted({s.motion_index for s in specs if s.split == split}) for split in SPLITS
        },
        "sequences": list(entries.values()),
    }
    todo = [s for s in specs if entries[s.name]["status"] == "pending" and s.split in splits]
    _write_manifest(folder, manifest)
    tasks = [(str(folder), config, spec) for spec in todo]

    def record(entry: dict[str, Any], done: int) -> None:
        entries[entry["name"]] = entry
        manifest["sequences"] = list(entries.values())
        _write_manifest(folder, manifest)
        if on_sequence is not None:
            on_sequence(entry, done, len(todo))

    if workers == 1 or len(tasks) <= 1:
        for done, task in enumerate(tasks, start=1):
            record(_run_task(task), done)
    else:
        context = multiprocessing.get_context("spawn")
        with context.Pool(min(workers, len(tasks)), torch.set_num_threads, (1,)) as pool:
            for done, entry in enumerate(pool.imap_unordered(_run_task, tasks), start=1):
                record(entry, done)
    return manifest
