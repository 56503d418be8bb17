"""``usd-garment eval``: collision, accuracy and stability figures of a garment layer."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    body_model_option,
    json_option,
    measure_workers_option,
    skeleton_option,
)
from usd_garment.eval.body_distance import body_pool
from usd_garment.eval.evaluate import evaluate_layer
from usd_garment.garment.template import LODS

#: Rows of the summary table: key, label, format.
ROWS = (
    ("inside_share", "vertices inside the body", "{:.3%}"),
    ("inside_forced_share", "  forced (limb pressed in body)", "{:.3%}"),
    ("inside_elsewhere_share", "  elsewhere (the method's)", "{:.3%}"),
    ("within_1mm_share", "vertices within 1 mm", "{:.3%}"),
    ("mean_penetration_mm", "mean penetration depth (mm)", "{:.3f}"),
    ("max_penetration_mm", "max penetration depth (mm)", "{:.3f}"),
    ("max_elsewhere_mm", "max depth elsewhere (mm)", "{:.3f}"),
    ("reference_mm", "mean distance to reference (mm)", "{:.3f}"),
    ("reference_shift_mm", "  whole-garment offset (mm)", "{:.3f}"),
    ("reference_unshifted_mm", "  without that offset (mm)", "{:.3f}"),
    ("acceleration", "mean vertex acceleration (m/s²)", "{:.3f}"),
    ("nan_count", "NaN vertices (all frames)", "{:d}"),
)


#: Body parts named in the summary's line on where the vertices inside elsewhere are.
PARTS_SHOWN = 5


def _cell(value: float | int | None, fmt: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return fmt.format(int(value) if fmt == "{:d}" else value)


@click.command("eval")
@click.argument("garment_layer", type=click.Path(path_type=Path))
@click.option(
    "--body",
    "body_input",
    type=click.Path(path_type=Path),
    required=True,
    help="The USD file with the animated body the garment was made for.",
)
@click.option(
    "--reference",
    type=click.Path(path_type=Path),
    default=None,
    help="Another garment layer to measure the distance to (e.g. a simulation).",
)
@click.option("--garment", default=None, help="Garment mesh name when the layer has several.")
@click.option(
    "--lod-variant",
    "lod",
    type=click.Choice(tuple(LODS)),
    default=None,
    help="Measure this variant of the garment's 'lod' variant set (a layer written with dress "
    "--lod-variants; default: the selected one). The file is not changed.",
)
@body_model_option
@skeleton_option
@click.option("--per-frame", is_flag=True, help="Also print one row per frame.")
@measure_workers_option
@json_option("Print summary and per-frame figures as JSON.")
def evaluate(
    garment_layer: Path,
    body_input: Path,
    reference: Path | None,
    garment: str | None,
    lod: str | None,
    body_model: Path | None,
    skeleton: str | None,
    per_frame: bool,
    workers: int,
    as_json: bool,
) -> None:
    """Collisions, distance to a reference, jitter and NaNs of GARMENT_LAYER on its body."""
    with user_errors(), body_pool(workers) as pool:
        metrics, time_codes = evaluate_layer(
            garment_layer, body_input, reference, garment, body_model, skeleton, pool, lod
        )
    if as_json:
        click.echo(json.dumps({"time_codes": time_codes.tolist(), **metrics.to_json()}, indent=2))
        return
    summary = metrics.summary()
    click.echo(f"{garment_layer}: {len(time_codes)} frames")
    for key, label, fmt in ROWS:
        click.echo(f"  {label:<34}{_cell(summary[key], fmt)}")
    parts = metrics.elsewhere_by_part()
    if parts:
        top = list(parts.items())[:PARTS_SHOWN]
        shares = ", ".join(f"{name} {share:.1%}" for name, share in top)
        click.echo(f"  inside elsewhere by body part (closest point): {shares}")
    if per_frame:
        table = metrics.per_frame()
        click.echo("time   " + "  ".join(f"{k:>20}" for k, _, _ in ROWS))
        for i, t in enumerate(time_codes.tolist()):
            cells = "  ".join(f"{_cell(table[k][i].item(), fmt):>20}" for k, _, fmt in ROWS)
            click.echo(f"{t:<7g}{cells}")
