"""``usd-garment project``: project simulated garment layers to the canonical space of the garment
model and write the training set file."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from usd_garment.canonical.project_layers import project_layers
from usd_garment.canonical.projection import ProjectionSettings
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    FrameProgress,
    body_model_option,
    fields_option,
    lod_option,
    split_list,
    splits_option,
    workers_option,
)
from usd_garment.garment.template import GARMENT_NAMES
from usd_garment.training.dataset import dataset_layers


@click.command("project")
@click.argument("sim_layers", metavar="[SIM_LAYER]...", nargs=-1, type=click.Path(path_type=Path))
@click.option(
    "--body",
    "body_layers",
    multiple=True,
    type=click.Path(path_type=Path),
    help="Animated body layer of each SIM_LAYER, in the same order (repeat), or one for all.",
)
@click.option(
    "--manifest",
    type=click.Path(path_type=Path),
    default=None,
    help="A 'dataset make' folder (or its manifest.json): project its ok sequences instead of "
    "SIM_LAYER... (garment and lod from the manifest).",
)
@splits_option("With --manifest: comma-separated splits to project.")
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Canonical training set to write (.npz).",
)
@click.option("--garment", type=click.Choice(GARMENT_NAMES), default="tshirt", show_default=True)
@lod_option
@click.option(
    "--iterations",
    type=click.IntRange(0),
    default=ProjectionSettings.iterations,
    show_default=True,
    help="Most L-BFGS iterations per chunk of frames.",
)
@click.option(
    "--strain-weight",
    type=click.FloatRange(0.0),
    default=ProjectionSettings.strain_weight,
    show_default=True,
    help="ω1 of E_strain (m²): keeps the canonical garment close to the template's triangles; "
    "lower fits the simulation closer where posing folds the cloth (see docs/canonical.md).",
)
@click.option(
    "--chunk",
    type=click.IntRange(1),
    default=ProjectionSettings.chunk,
    show_default=True,
    help="Frames optimised together, each warm-started from the last solved frame.",
)
@workers_option
@click.option(
    "--update",
    is_flag=True,
    help="If OUTPUT exists, keep its sequences and project only the layers it lacks (a dataset "
    "that grew, a simulation run that finished later); a set projected before flagged frames "
    "were recorded gets them from its layers.",
)
@body_model_option
@fields_option
def project(
    sim_layers: tuple[Path, ...],
    body_layers: tuple[Path, ...],
    manifest: Path | None,
    split_names: str,
    output: Path,
    garment: str,
    lod: str,
    iterations: int,
    strain_weight: float,
    chunk: int,
    workers: int,
    update: bool,
    body_model: Path | None,
    fields: Path | None,
) -> None:
    """Project the simulated garments of SIM_LAYER... (or of a dataset's --manifest) to
    canonical space; write OUTPUT."""
    settings = ProjectionSettings(iterations=iterations, strain_weight=strain_weight, chunk=chunk)
    splits = None
    with user_errors():
        if manifest is not None:
            if sim_layers or body_layers:
                raise click.UsageError("give either SIM_LAYER... with --body, or --manifest")
            layers = dataset_layers(manifest, split_list(split_names))
            sim_layers, body_layers = tuple(layers.garments), tuple(layers.bodies)
            garment, lod, splits = layers.garment, layers.lod, layers.splits
        elif not sim_layers or not body_layers:
            raise click.UsageError("give SIM_LAYER... and --body, or --manifest")
    with FrameProgress("project") as bar, user_errors():
        data, written = project_layers(
            sim_layers, body_layers, output, garment=garment, lod=lod,
            body_model=body_model, fields=fields, settings=settings, splits=splits,
            workers=workers, update=update, on_read=bar.on_read, progress=bar.progress,
        )  # fmt: skip
    run = data.metadata["last_run"]
    if run["sequences"]:
        wall, frames = float(run["wall_seconds"]), int(run["frames"])
        rate, alone = frames / max(wall, 1e-9), frames / max(float(run["seconds"]), 1e-9)
        done = (
            f"{run['sequences']} sequence(s), {frames} frames projected in {wall:.1f} s with "
            f"{run['workers']} worker(s) ({rate:.2f} frames/s; projection alone {alone:.2f} "
            "frames/s per worker)"
        )
    else:
        done = "no layer new to it"
    mean_mm, max_mm = 1e3 * float(np.mean(data.error)), 1e3 * float(np.max(data.max_error))
    click.echo(
        f"{done}; the set: {data.num_sequences} sequences, {len(data.canonical)} frames, "
        f"reprojection error mean {mean_mm:.2f} mm, max {max_mm:.2f} mm"
    )
    if data.flagged is None:
        click.echo("frames the simulation flagged: not recorded (a layer of the set is gone)")
    else:
        flagged = int(np.sum(data.flagged))
        sequences = sum(bool(np.any(data.flagged[data.sequence(s)]))
                        for s in range(data.num_sequences))  # fmt: skip
        click.echo(f"frames the simulation flagged: {flagged} in {sequences} sequence(s)")
    if written:
        click.echo(f"wrote {output}")
    else:
        click.echo(f"{output} left as it was")
