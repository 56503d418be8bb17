"""``usd-garment garment``: inspect and rebuild the procedural garment templates."""

from __future__ import annotations

import json
from pathlib import Path

import click

from usd_garment.body import load_body_model
from usd_garment.body.fingerprint import rest_fingerprint
from usd_garment.cli.drape import drape
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import body_model_option, json_option, lod_option
from usd_garment.garment.library import (
    Provenance,
    cache_dir,
    load_template,
    save_template,
    template_dir,
    template_filename,
)
from usd_garment.garment.summary import garment_summary
from usd_garment.garment.template import GARMENT_NAMES, LODS, RECIPE_VERSION
from usd_garment.garment.templates import build_templates


@click.group()
def garment() -> None:
    """Garment templates: inspect, rebuild."""


@garment.command("info")
@click.argument("name", type=click.Choice(GARMENT_NAMES))
@lod_option
@body_model_option
@json_option()
def info(name: str, lod: str, body_model: Path | None, as_json: bool) -> None:
    """Vertices, faces, boundary loops and clearance to the rest body of a garment template."""
    with user_errors():
        template = load_template(name, lod, body_model)
        summary = garment_summary(template, load_body_model(body_model))
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"garment      {summary['name']} ({summary['lod']}), body {summary['body']}")
    click.echo(f"vertices     {summary['vertices']}")
    click.echo(f"faces        {summary['faces']}")
    loops = ", ".join(f"{lp['opening']} {lp['vertices']}" for lp in summary["loops"])
    click.echo(f"boundary loops  {summary['boundary_loops']}: {loops}")
    click.echo(
        f"clearance to the rest body  min {1e3 * summary['clearance_min_m']:.1f} mm, "
        f"median {1e3 * summary['clearance_median_m']:.1f} mm"
    )
    click.echo(
        f"edge length  mean {1e3 * summary['edge_length_mean_m']:.1f} mm, "
        f"CV {summary['edge_length_cv']:.3f}"
    )


@garment.command("build")
@body_model_option
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for the template files; default: the package data (default body) or the cache.",
)
def build(body_model: Path | None, output: Path | None) -> None:
    """Rebuild the templates of every garment and level of detail for a body model."""
    with user_errors():
        model = load_body_model(body_model)
        provenance = Provenance(rest_fingerprint(model), RECIPE_VERSION)
        if output is None:
            key = f"{provenance.body_fingerprint}-v{RECIPE_VERSION}"
            output = template_dir() if body_model is None else cache_dir() / key
        output.mkdir(parents=True, exist_ok=True)
        with click.progressbar(
            length=len(GARMENT_NAMES) * len(LODS), label="building garment templates"
        ) as bar:
            for name in GARMENT_NAMES:
                for template in build_templates(model, name):
                    path = output / template_filename(name, template.lod)
                    save_template(path, template, provenance)
                    bar.update(1)
    click.echo(f"wrote {len(GARMENT_NAMES) * len(LODS)} templates to {output}")


garment.add_command(drape)
