"""``usd-garment dataset``: make training data (simulated garments on procedural motions × random
body shapes) with a manifest."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click
import numpy as np
from tqdm import tqdm

from usd_garment.body.io import load_body_model
from usd_garment.canonical.dataset import load_canonical_set
from usd_garment.canonical.floor import (
    NetworkFloor,
    SequenceFloor,
    network_floor,
    representation_floor,
)
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    FrameProgress,
    body_model_option,
    collars_option,
    fields_option,
    json_option,
    lod_option,
    solver_options,
    split_list,
    splits_option,
    workers_option,
)
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.template import GARMENT_NAMES
from usd_garment.sim.material import ClothMaterial
from usd_garment.training.data_quality import (
    GROUPINGS,
    GroupQuality,
    SequenceChange,
    compare_manifests,
    dataset_quality,
)
from usd_garment.training.dataset import (
    DATASET_KINDS,
    MANIFEST_NAME,
    SPLITS,
    DatasetConfig,
    check_splits,
    make_dataset,
    read_manifest,
)


def _capture(text: str) -> tuple[str, str]:
    """``FILE:SPLIT`` of ``--capture`` as ``(file, split)``."""
    path, sep, split = text.rpartition(":")
    if not sep or not path:
        raise click.BadParameter(f"expected FILE:SPLIT, got {text!r}", param_hint="--capture")
    return path, split


@click.group()
def dataset() -> None:
    """Training data: simulated garment sequences."""


@dataset.command("make")
@click.option("--garment", type=click.Choice(GARMENT_NAMES), default="tshirt", show_default=True)
@click.option(
    "--motions",
    type=click.IntRange(0),
    default=12,
    show_default=True,
    help="Procedural motions (0: the captures alone).",
)
@click.option("--shapes", type=click.IntRange(1), default=3, show_default=True)
@click.option("--frames", type=click.IntRange(1), default=90, show_default=True)
@lod_option
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--shape-sigma",
    type=click.FloatRange(min=0.0, min_open=True),
    default=1.0,
    show_default=True,
    help="Body shapes: betas standard normal, clipped to ±sigma.",
)
@click.option(
    "--open-shoulders",
    is_flag=True,
    help="Procedural motions keep the arms clear of the torso (default: arms may hang "
    "against the trunk, as in capture).",
)
@click.option(
    "--train-only",
    is_flag=True,
    help="Every procedural motion in the train split: extra training data for a model whose "
    "validation and test motions come from another dataset (captures keep their split).",
)
@click.option(
    "--kinds",
    default=",".join(DATASET_KINDS),
    show_default=True,
    help="Comma-separated procedural motion kinds the motions rotate through "
    "('usd-garment motion kinds' lists them; 'hop' is not in the default).",
)
@click.option(
    "--shape-per-motion",
    is_flag=True,
    help="Each procedural motion on SHAPES random body shapes of its own (none is the mean "
    "shape): many shapes from few sequences (captures keep the shared shapes).",
)
@click.option(
    "--capture",
    "captures",
    multiple=True,
    metavar="FILE:SPLIT",
    help="A real motion (.bvh, .bvh.xz or .bvh.gz; .amc with its .asf beside it; an AMASS .npz "
    "or a USD body layer) and its split (train, validation or test), played whole; repeat for "
    "several.",
)
@click.option(
    "--capture-shapes",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="How many of the body shapes each capture is simulated on (the first ones).",
)
@collars_option("BVH captures: the collars as import-bvh --collars retargets them.")
@solver_options
@workers_option
@click.option("--resume", is_flag=True, help="Finish the dataset already in OUTPUT.")
@splits_option(
    "Comma-separated splits to simulate (e.g. 'test' for a benchmark); the other sequences "
    "stay pending for a later --resume."
)
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Dataset folder (created).",
)
@json_option("Print the manifest's summary as JSON.")
def make(
    garment: str,
    motions: int,
    shapes: int,
    frames: int,
    lod: str,
    seed: int,
    shape_sigma: float,
    open_shoulders: bool,
    train_only: bool,
    kinds: str,
    shape_per_motion: bool,
    captures: tuple[str, ...],
    capture_shapes: int,
    collars: str,
    substeps: int,
    iterations: int,
    material: Path | None,
    workers: int,
    resume: bool,
    split_names: str,
    output: Path,
    as_json: bool,
) -> None:
    """Simulate GARMENT on MOTIONS procedural motions × SHAPES body shapes, and on the
    captures, into OUTPUT."""
    bar: tqdm | None = None

    def on_sequence(entry: dict[str, Any], done: int, total: int) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, desc="sequences", unit="seq", disable=None)
        bar.update(done - bar.n)
        if entry["status"] == "error":
            tqdm.write(f"sequence {entry['name']} failed (--resume retries): {entry['message']}")
        elif entry["status"] != "ok":
            tqdm.write(f"bad sequence {entry['name']}: {entry['message']}")

    try:
        with user_errors():
            fabric = ClothMaterial.load(material) if material is not None else ClothMaterial()
            config = DatasetConfig(
                garment=garment, lod=lod, motions=motions, shapes=shapes, frames=frames,
                seed=seed, substeps=substeps, iterations=iterations, material=fabric,
                shape_sigma=shape_sigma, open_shoulders=open_shoulders, train_only=train_only,
                captures=tuple(_capture(text) for text in captures),
                capture_shapes=capture_shapes, kinds=tuple(split_list(kinds)),
                shape_per_motion=shape_per_motion, collars=collars,
            )  # fmt: skip
            splits = split_list(split_names)
            manifest = make_dataset(
                output, config, workers=workers, resume=resume, splits=splits,
                on_sequence=on_sequence,
            )  # fmt: skip
    finally:
        if bar is not None:
            bar.close()
    summary = manifest["summary"]
    errors = summary["errors"]
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        pending = summary["sequences"] - summary["ok"] - summary["bad"] - errors
        click.echo(
            f"{summary['ok']} of {summary['sequences']} sequences ok ({summary['bad']} bad"
            f"{f', {errors} failed with an error' if errors else ''}"
            f"{f', {pending} pending' if pending else ''}), {summary['frames_ok']} frames, "
            f"{summary['bytes'] / 1e6:.1f} MB; "
            f"manifest {output / MANIFEST_NAME}"
        )
    if errors:
        raise SystemExit(1)


@dataset.command("floor")
@click.argument("canonical", type=click.Path(dir_okay=False, path_type=Path))
@splits_option("Comma-separated splits to measure.")
@body_model_option
@fields_option
@click.option(
    "--model", "model_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
    help="A trained model directory: also split its error on the targets into the decoder's "
    "best fit and the networks' prediction (canonical space).",
)  # fmt: skip
@json_option("Print every sequence's figures as JSON.")
def floor(
    canonical: Path,
    split_names: str,
    body_model: Path | None,
    fields: Path | None,
    model_dir: Path | None,
    as_json: bool,
) -> None:
    """How close a model trained on the canonical set CANONICAL can come to its simulations:
    each sequence's targets posed back by the garment model, beside the simulation, both
    measured against the posed body (winding number: inside forced / elsewhere); with --model,
    how close that model's decoder can come to the targets and how close its networks do."""
    with user_errors():
        splits = split_list(split_names)
        check_splits(splits)
        data = load_canonical_set(canonical)
        body = load_body_model(body_model)
        body_fields = load_body_fields(fields)
        model = None
        if model_dir is not None:
            from usd_garment.methods.learned_model import load_learned_model

            model = load_learned_model(model_dir, body)
        total = sum(1 for s in data.splits if s in splits)
        with FrameProgress("floor", unit="seq") as bar:
            bar.on_read(total)
            rows = representation_floor(data, body, body_fields, splits, bar.progress)
        networks: list[NetworkFloor] = []
        if model is not None:
            with FrameProgress("networks", unit="seq") as bar:
                bar.on_read(total)
                networks = network_floor(data, model, splits, bar.progress)
    if as_json:
        entries = [row.to_json() for row in rows]
        for entry, net in zip(entries, networks, strict=False):
            entry |= {"decoder_fit_mm": net.decoder_fit_mm, "networks_mm": net.networks_mm}
        click.echo(json.dumps(entries, indent=2))
        return
    click.echo(_floor_table(rows))
    if networks:
        click.echo(_networks_table(networks))


Row = TypeVar("Row", SequenceFloor, NetworkFloor)


def _split_table(header: str, rows: list[Row], line: Callable[[str, str, list[Row]], str]) -> str:
    """``header``, one ``line`` per sequence, then one per split over its sequences."""
    lines = [header] + [line(Path(r.source).stem, r.split, [r]) for r in rows]
    for split in SPLITS:
        group = [r for r in rows if r.split == split]
        if group:
            lines.append(line("all", split, group))
    return "\n".join(lines)


def _floor_table(rows: list[SequenceFloor]) -> str:
    """Per sequence, then frame-weighted means per split: reprojection error (mm) and the
    inside shares (%) of the simulation and of the targets posed back."""
    header = (
        "sequence | split | frames | reprojection mm | simulation forced / elsewhere % "
        "| posed back forced / elsewhere %"
    )

    def line(name: str, split: str, group: list[SequenceFloor]) -> str:
        w = np.array([r.frames for r in group], dtype=float)

        def mean(values: list[float]) -> float:
            return float(np.dot(w, values) / w.sum())

        def pct(part: str, key: str) -> str:
            return f"{100 * mean([getattr(r, part)[key] for r in group]):.3f}"

        return (
            f"{name} | {split} | {int(w.sum())} | {mean([r.reprojection_mm for r in group]):.2f} "
            f"| {pct('simulation', 'inside_forced_share')} / "
            f"{pct('simulation', 'inside_elsewhere_share')} "
            f"| {pct('reposed', 'inside_forced_share')} / "
            f"{pct('reposed', 'inside_elsewhere_share')}"
        )

    return _split_table(header, rows, line)


def _networks_table(rows: list[NetworkFloor]) -> str:
    """Per sequence, then frame-weighted means per split: the decoder's best fit and the
    networks' prediction against the targets (mm, canonical space)."""
    header = "sequence | split | frames | decoder best fit mm | networks mm"

    def line(name: str, split: str, group: list[NetworkFloor]) -> str:
        w = np.array([r.frames for r in group], dtype=float)
        fit = np.dot(w, [r.decoder_fit_mm for r in group]) / w.sum()
        net = np.dot(w, [r.networks_mm for r in group]) / w.sum()
        return f"{name} | {split} | {int(w.sum())} | {fit:.2f} | {net:.2f}"

    return _split_table(header, rows, line)


@dataset.command("summary")
@click.argument("folder", type=click.Path(path_type=Path))
@click.option(
    "--by", type=click.Choice(GROUPINGS), default="split", show_default=True,
    help="Group the sequences per split, per motion kind (each capture alone) or not at all.",
)  # fmt: skip
@json_option("Print every group's figures as JSON.")
def summary(folder: Path, by: str, as_json: bool) -> None:
    """The simulation checks of the dataset in FOLDER (from its manifest, or of the manifest file
    FOLDER, e.g. one committed in docs/datasets), summed up: inside the
    body forced / elsewhere, distance from the body, stretch (p99 and the largest single edge),
    NaN, retried and bad frames."""
    with user_errors():
        rows = dataset_quality(read_manifest(folder), by)
    if as_json:
        click.echo(json.dumps([row.to_json() for row in rows], indent=2))
        return
    click.echo(_summary_table(rows))


def _summary_table(rows: list[GroupQuality]) -> str:
    """One line per group; shares in %, distance in cm, time in minutes."""
    lines = [
        "group | ok / sequences | frames | forced mean % | elsewhere mean / worst frame % "
        "| sequences above 0.05 % mean / 0.5 % frame | farthest cm (sequences > 10 cm) "
        "| stretch p99 max (largest edge) | NaN / retried / bad frames | simulation min"
    ]
    for r in rows:
        largest = "–" if r.stretch_max is None else f"{r.stretch_max:.2f}"
        lines.append(
            f"{r.group} | {r.ok} / {r.sequences} | {r.frames} | {100 * r.forced_mean:.3f} "
            f"| {100 * r.elsewhere_mean:.3f} / {100 * r.elsewhere_max:.3f} "
            f"| {r.above_mean} / {r.above_frame} | {100 * r.max_distance_m:.1f} ({r.far}) "
            f"| {r.stretch_p99_max:.3f} ({largest}) | {r.nan_frames} / {r.retried_frames} / "
            f"{r.bad_frames} "
            f"| {r.seconds / 60:.1f}"
        )
    return "\n".join(lines)


@dataset.command("compare")
@click.argument("before", type=click.Path(exists=True, path_type=Path))
@click.argument("now", type=click.Path(exists=True, path_type=Path))
@json_option("Print every sequence's comparison as JSON.")
def compare(before: Path, now: Path, as_json: bool) -> None:
    """A dataset made again (NOW: its folder or manifest) against the manifest it had (BEFORE,
    e.g. one committed in docs/datasets), sequence by sequence: the same simulation gives the
    same checks (all but its time). A changed sequence shows how far apart its figures are (the
    largest relative change). The last line counts the sequences that came out the same."""
    with user_errors():
        rows = compare_manifests(read_manifest(before), read_manifest(now))
    if as_json:
        click.echo(json.dumps([row.to_json() for row in rows], indent=2))
        return
    click.echo(_compare_table(rows))


def _compare_table(rows: list[SequenceChange]) -> str:
    """One line per sequence (before → now), then the count of those that came out the same."""

    def figures(checks: dict[str, Any]) -> str:
        if not checks:
            return "–"
        largest = checks.get("stretch_max")
        edge = "" if largest is None else f" ({largest:.2f})"
        return (
            f"{len(checks['retries'])} / {checks['bad_frames']}, "
            f"{checks['stretch_p99_max']:.3f}{edge}"
        )

    lines = ["sequence | kind | status | retried / bad frames, stretch p99 max (largest edge): "
             "before | now | verdict"]  # fmt: skip
    for r in rows:
        largest = r.largest_relative_change
        by = "" if largest is None else f" (by {largest:.1e} relative at most)"
        verdict = "same" if r.same else f"changed{by}: " + ", ".join(r.changed)
        lines.append(
            f"{r.name} | {r.kind} | {' → '.join(r.status)} | {figures(r.before)} | "
            f"{figures(r.now)} | {verdict}"
        )
    same = sum(r.same for r in rows)
    pending = sum(r.status[1] == "pending" for r in rows)
    lines.append(f"{same} of {len(rows)} sequences came out the same"
                 + (f" ({pending} not made yet)" if pending else ""))  # fmt: skip
    return "\n".join(lines)
