"""``usd-garment project``: project simulated garment layers to the canonical space of the garment
model and write the training set file."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from usd_garment.canonical.project_layers import project_layers
from usd_garment.canonical.projection import ProjectionSettings
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import FrameProgress, body_model_option, lod_option
from usd_garment.garment.template import GARMENT_NAMES


@click.command("project")
@click.argument(
    "sim_layers", metavar="SIM_LAYER...", nargs=-1, required=True, type=click.Path(path_type=Path)
)
@click.option(
    "--body",
    "body_layers",
    multiple=True,
    required=True,
    type=click.Path(path_type=Path),
    help="Animated body layer of each SIM_LAYER, in the same order (repeat), or one for all.",
)
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
    "--chunk",
    type=click.IntRange(1),
    default=ProjectionSettings.chunk,
    show_default=True,
    help="Frames optimised together, each warm-started from the last solved frame.",
)
@body_model_option
@click.option(
    "--fields",
    type=click.Path(path_type=Path),
    default=None,
    help="Diffused body fields of that body; default: the embedded body's.",
)
def project(
    sim_layers: tuple[Path, ...],
    body_layers: tuple[Path, ...],
    output: Path,
    garment: str,
    lod: str,
    iterations: int,
    chunk: int,
    body_model: Path | None,
    fields: Path | None,
) -> None:
    """Project the simulated garments of SIM_LAYER... to canonical space; write OUTPUT."""
    settings = ProjectionSettings(iterations=iterations, chunk=chunk)
    with FrameProgress("project") as bar, user_errors():
        data = project_layers(
            sim_layers, body_layers, output, garment=garment, lod=lod,
            body_model=body_model, fields=fields, settings=settings,
            on_read=bar.on_read, progress=bar.progress,
        )  # fmt: skip
    seconds = float(data.metadata["seconds"])
    frames = len(data.canonical)
    mean_mm, max_mm = 1e3 * float(np.mean(data.error)), 1e3 * float(np.max(data.max_error))
    click.echo(
        f"{data.num_sequences} sequences, {frames} frames in {seconds:.1f} s "
        f"({frames / max(seconds, 1e-9):.2f} frames/s); reprojection error mean "
        f"{mean_mm:.2f} mm, max {max_mm:.2f} mm"
    )
    click.echo(f"wrote {output}")
