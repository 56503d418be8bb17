"""Entry point of the ``usd-garment`` command: registers the command groups."""

from __future__ import annotations

import click

from usd_garment import __version__
from usd_garment.cli.amass import export_amass, import_amass
from usd_garment.cli.bench import bench
from usd_garment.cli.body import body
from usd_garment.cli.bvh import import_bvh
from usd_garment.cli.dataset import dataset
from usd_garment.cli.drape import drape
from usd_garment.cli.dress import dress
from usd_garment.cli.evaluate import evaluate
from usd_garment.cli.fields import fields
from usd_garment.cli.garment import garment
from usd_garment.cli.motion import motion
from usd_garment.cli.project import project
from usd_garment.cli.simulate import simulate
from usd_garment.cli.train import train


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="usd-garment")
def main() -> None:
    """Dress animated SMPL bodies in USD with learned, collision-free garments."""


main.add_command(body)
main.add_command(garment)
garment.add_command(drape)
main.add_command(import_amass)
main.add_command(export_amass)
main.add_command(import_bvh)
main.add_command(dress)
main.add_command(evaluate)
main.add_command(simulate)
main.add_command(dataset)
main.add_command(motion)
main.add_command(fields)
main.add_command(project)
main.add_command(train)
main.add_command(bench)
