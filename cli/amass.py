"""``usd-garment import-amass`` / ``export-amass``: AMASS ``.npz`` motions to USD body layers
and back."""

from __future__ import annotations

from pathlib import Path

import click

from usd_garment.body import load_body_model
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    body_layer_output_option,
    body_model_option,
    resample_fps_option,
    skeleton_option,
)
from usd_garment.motion.amass import load_amass, save_amass
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.read import read_smpl_motion

USD_SUFFIXES = (".usd", ".usda", ".usdc")


@click.command("import-amass")
@click.argument("npz", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@body_layer_output_option
@resample_fps_option
@body_model_option
def import_amass(npz: Path, output: Path, fps: float | None, body_model: Path | None) -> None:
    """Convert an AMASS motion (.npz, Z-up) into a USD body layer (Y-up, metres)."""
    if output.suffix.lower() not in USD_SUFFIXES:
        raise click.BadParameter("the output must end in .usda, .usdc or .usd", param_hint="-o")
    if output.resolve() == npz.resolve():
        raise click.BadParameter("the output must not overwrite the input", param_hint="-o")
    with user_errors():
        body = load_body_model(body_model)
        motion = load_amass(npz, body, fps)
        write_body_layer(output, motion, body)
    click.echo(f"wrote {output}: {motion.num_frames} frames at {motion.fps:g} fps")


@click.command("export-amass")
@click.argument("usd", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="AMASS-style .npz to write.",
)
@skeleton_option
@body_model_option
def export_amass(usd: Path, output: Path, skeleton: str | None, body_model: Path | None) -> None:
    """Write the SMPL motion of a USD skeleton as an AMASS .npz (Z-up, SMPL-H layout)."""
    if output.suffix.lower() != ".npz":
        raise click.BadParameter("the output must end in .npz", param_hint="-o")
    if output.resolve() == usd.resolve():
        raise click.BadParameter("the output must not overwrite the input", param_hint="-o")
    with user_errors():
        body = load_body_model(body_model)
        motion, _ = read_smpl_motion(usd, body, skeleton=skeleton)
        save_amass(output, motion, body)
    click.echo(f"wrote {output}: {motion.num_frames} frames at {motion.fps:g} fps")
