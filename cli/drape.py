"""``usd-garment garment drape``: settle garment templates under gravity on the rest body with the
cloth simulator and store the draped templates."""

from __future__ import annotations

import json
from pathlib import Path

import click

from usd_garment.body import load_body_model
from usd_garment.body.fingerprint import rest_fingerprint
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import body_model_option
from usd_garment.garment.library import (
    Provenance,
    body_cache_dir,
    load_template,
    save_template,
    template_dir,
    template_filename,
)
from usd_garment.garment.template import GARMENT_NAMES, LODS, RECIPE_VERSION
from usd_garment.sim.drape import drape_template


@click.command("drape")
@click.argument("name", type=click.Choice(GARMENT_NAMES))
@click.option(
    "--lod",
    "lods",
    type=click.Choice(tuple(LODS)),
    multiple=True,
    help="Level of detail (repeatable); default: all.",
)
@body_model_option
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for the draped files; default: the package data (default body) or the cache.",
)
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary.")
def drape(
    name: str, lods: tuple[str, ...], body_model: Path | None, output: Path | None, as_json: bool
) -> None:
    """Settle template NAME under gravity on the rest body; write NAME_LOD_draped.npz."""
    reports = []
    with user_errors():
        model = load_body_model(body_model)
        provenance = Provenance(rest_fingerprint(model), RECIPE_VERSION)
        folder = output or (template_dir() if body_model is None else body_cache_dir(model))
        folder.mkdir(parents=True, exist_ok=True)
        for lod in lods or tuple(LODS):
            result = drape_template(load_template(name, lod, body_model), model)
            path = folder / template_filename(name, lod, draped=True)
            save_template(path, result.template, provenance)
            reports.append({**result.to_json(), "path": str(path)})
            if not as_json:
                click.echo(
                    f"{name} {lod}: {result.frames} frames (max speed "
                    f"{1e3 * result.max_speed:.1f} mm/s), rest-length error median "
                    f"{100 * result.rest_length_error_median:.2f}% p99 "
                    f"{100 * result.rest_length_error_p99:.2f}%, {result.inside_count} vertices "
                    f"inside the body, clearance min {1e3 * result.clearance_min:.1f} mm median "
                    f"{1e3 * result.clearance_median:.1f} mm, sag {1e3 * result.sag:.1f} mm"
                    f"\n  wrote {path}"
                )
    if as_json:
        click.echo(json.dumps(reports, indent=2))
