"""Entry point of the ``usd-garment`` command: registers the command groups.

Each command's module is imported when that command runs (or when help lists it), so that
``usd-garment dress`` does not pay for the imports of training, simulation and the bench.
"""

from __future__ import annotations

import signal
import sys
from importlib import import_module
from types import FrameType

import click

from usd_garment import __version__
from usd_garment.cli.allocator import keep_freed_memory

#: Command name → ``module:attribute`` of its click command, under ``usd_garment.cli``.
COMMANDS = {
    "body": "body:body",
    "garment": "garment:garment",
    "import-amass": "amass:import_amass",
    "export-amass": "amass:export_amass",
    "import-bvh": "bvh:import_bvh",
    "dress": "dress:dress",
    "eval": "evaluate:evaluate",
    "simulate": "simulate:simulate",
    "dataset": "dataset:dataset",
    "motion": "motion:motion",
    "fields": "fields:fields",
    "project": "project:project",
    "train": "train:train",
    "bench": "bench:bench",
}


class LazyGroup(click.Group):
    """A group whose subcommands (:data:`COMMANDS`) are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        module, _, attribute = COMMANDS[cmd_name].partition(":")
        command: click.Command = getattr(import_module(f"usd_garment.cli.{module}"), attribute)
        return command


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="usd-garment")
def main() -> None:
    """Dress animated SMPL bodies in USD with learned, collision-free garments."""
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    keep_freed_memory()


def _exit_on_sigterm(signum: int, _frame: FrameType | None) -> None:
    """``kill`` ends a command as Ctrl-C does, through its ``with`` blocks: worker pools are
    terminated (orphaned workers of a killed ``dataset make`` went on writing into its folder)
    and temporary files removed; exit status 128 + the signal's number."""
    sys.exit(128 + signum)
