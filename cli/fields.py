"""``usd-garment fields``: fit the diffused body fields and the canonical SDF, and inspect them."""

from __future__ import annotations

import json
from pathlib import Path

import click
from tqdm import tqdm

from usd_garment.atomic import atomic_output
from usd_garment.body import load_body_model
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import body_model_option, json_option
from usd_garment.fields import default_fields_path, load_body_fields, save_body_fields


@click.group()
def fields() -> None:
    """Diffused body fields (skinning weights, blendshapes) and the canonical body SDF."""


@fields.command("fit")
@body_model_option
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Fields file to write (.npz); default: the default body's fields of this install.",
)
@click.option(
    "--method",
    type=click.Choice(["direct", "mlp"]),
    default="direct",
    show_default=True,
    help="direct: the diffusion computed at every grid node; mlp: MLPs fitted to the diffusion "
    "at sampled points (as in the paper), then baked into the grids.",
)
@click.option(
    "--samples", type=click.IntRange(min=100), default=None, help="Training points (mlp)."
)
@click.option(
    "--diffusion-samples",
    type=click.IntRange(min=1),
    default=None,
    help="N, Gaussian samples averaged per training point.",
)
@click.option("--seed", type=int, default=None, help="Random seed.")
@click.option("--epochs", type=click.IntRange(min=1), default=None, help="Epochs per MLP (mlp).")
def fit(
    body_model: Path | None,
    output: Path | None,
    method: str,
    samples: int | None,
    diffusion_samples: int | None,
    seed: int | None,
    epochs: int | None,
) -> None:
    """Fit the fields of a body model and bake them into grids (needs the [train] extra)."""
    if method == "direct" and (samples is not None or epochs is not None):
        raise click.UsageError("--samples and --epochs apply to --method mlp only")
    from usd_garment.fields.fit import fit_body_fields

    output = default_fields_path() if output is None else output
    if output.suffix.lower() != ".npz":
        raise click.BadParameter("the output must end in .npz", param_hint="-o")
    given = {"method": method, "samples": samples, "diffusion_samples": diffusion_samples}
    given |= {"seed": seed, "epochs": epochs}
    bars: dict[str, tqdm] = {}

    def progress(stage: str, done: int, total: int) -> None:
        bar = bars.get(stage)
        if bar is None:
            for old in bars.values():
                old.close()
            bar = bars[stage] = tqdm(total=total, desc=stage, unit="", leave=True)
        bar.update(done - bar.n)

    with user_errors():
        body = load_body_model(body_model)
        result = fit_body_fields(body, **given, progress=progress)
        for bar in bars.values():
            bar.close()
        result.config["command"] = "usd-garment fields fit " + " ".join(
            f"--{k.replace('_', '-')} {v}" for k, v in given.items() if v is not None
        )
        save_body_fields(output, result)
        config_path = output.with_suffix(".json")
        with atomic_output(config_path) as tmp, tmp.open("w") as fh:
            json.dump(result.config, fh, indent=2)
            fh.write("\n")
    click.echo(f"wrote {output} and {config_path}")


@fields.command("info")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path), required=False)
@json_option()
def info(file: Path | None, as_json: bool) -> None:
    """Grids, sizes and fitting settings of a fields file (default: the default body's)."""
    with user_errors():
        summary = load_body_fields(file).summary()
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"body               {summary['body']}")
    click.echo(f"pose blendshapes   {'yes' if summary['pose_dirs'] else 'no'}")
    for i, level in enumerate(summary["field_levels"]):
        click.echo(
            f"field level {i}      {level['spacing_m'] * 100:g} cm, {level['band_nodes']} nodes"
            f" ({', '.join(level['groups'])})"
        )
    click.echo(f"field coarse box   {summary['fields_coarse']['spacing_m'] * 100:g} cm")
    sdf = summary["sdf_grid"]
    click.echo(
        f"sdf                {sdf['spacing_m'] * 1000:g} mm band ({sdf['band_nodes']} nodes), "
        f"{sdf['coarse_spacing_m'] * 100:g} cm box"
    )
    config = summary["config"]
    keys = ("method", "samples", "diffusion_samples", "epochs", "seed", "final_losses")
    keys += ("timings_s",)
    for key in keys:
        if key in config:
            click.echo(f"{key:<18} {config[key]}")
