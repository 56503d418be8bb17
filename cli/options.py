"""Options and progress display shared by several commands, so each is declared once."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any, TypeVar

import click
import numpy as np
from tqdm import tqdm

from usd_garment.garment.template import LODS

F = TypeVar("F", bound=Callable[..., Any])

body_model_option = click.option(
    "--body-model",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="SMPL-layout body file (.npz/.pkl); default: the embedded free body.",
)
fields_option = click.option(
    "--fields",
    type=click.Path(path_type=Path),
    default=None,
    help="Diffused body fields of that body; default: the embedded body's.",
)
workers_option = click.option(
    "--workers",
    type=click.IntRange(1),
    default=2,
    show_default=True,
    help="Processes, one sequence each at a time (one CPU core each).",
)
measure_workers_option = click.option(
    "--workers",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Processes that measure the garment against the body, blocks of 16 frames each (one "
    "CPU core each, ~2 s each to start); the same figures.",
)
skeleton_option = click.option(
    "--skeleton", default=None, help="Skeleton prim path when the stage has several."
)
lod_option = click.option(
    "--lod", type=click.Choice(tuple(LODS)), default="high", show_default=True,
    help="Garment level of detail.",
)  # fmt: skip


def _layer_output_option(what: str) -> Callable[[F], F]:
    """The required ``-o/--output`` file option of a command that writes ``what``."""
    return click.option(
        "-o",
        "--output",
        type=click.Path(dir_okay=False, path_type=Path),
        required=True,
        help=f"{what} to write (.usda, .usdc or .usd).",
    )


body_layer_output_option = _layer_output_option("USD body layer")
garment_layer_output_option = _layer_output_option("Garment layer")
resample_fps_option = click.option(
    "--fps", type=click.FloatRange(min=0, min_open=True), default=None,
    help="Resample to this frame rate (default: the file's own).",
)  # fmt: skip
frames_option = click.option(
    "--frames", default=None, help="Frames A:B of the stage's range (B exclusive)."
)


def solver_options(command: F) -> F:
    """The cloth solver's ``--substeps``, ``--iterations`` and ``--material`` options."""
    from usd_garment.sim.cloth import ITERATIONS, SUBSTEPS  # here: ``dress`` need not load it

    for option in reversed((
        click.option("--substeps", type=click.IntRange(1, 64), default=SUBSTEPS,
                     show_default=True, help="Solver substeps per 30 fps frame."),
        click.option("--iterations", type=click.IntRange(1, 64), default=ITERATIONS,
                     show_default=True, help="Solver iterations per substep."),
        click.option("--material", type=click.Path(dir_okay=False, path_type=Path), default=None,
                     help="Fabric JSON file (keys of ClothMaterial); default: SNUG cotton."),
    )):  # fmt: skip
        command = option(command)
    return command


def splits_option(help_text: str) -> Callable[[F], F]:
    """``--split``: comma-separated dataset splits, all by default, stored as ``split_names``."""
    from usd_garment.training.dataset import SPLITS  # here: ``dress`` need not load it

    return click.option(
        "--split", "split_names", default=",".join(SPLITS), show_default=True, help=help_text
    )


def collars_option(help_text: str) -> Callable[[F], F]:
    """``--collars aimed|rest``: how BVH captures' collar bones are retargeted (``import-bvh``)."""
    from usd_garment.motion.bvh import (
        COLLAR_MODES,
        DEFAULT_COLLARS,
    )  # here: ``dress`` need not load it

    return click.option(
        "--collars", type=click.Choice(COLLAR_MODES), default=DEFAULT_COLLARS,
        show_default=True, help=help_text,
    )  # fmt: skip


def split_list(split_names: str) -> list[str]:
    """The split names of a ``--split`` value (comma-separated, spaces ignored)."""
    return [s.strip() for s in split_names.split(",")]


def json_option(help_text: str = "Print a JSON summary on stdout.") -> Callable[[F], F]:
    """The ``--json`` flag, stored as ``as_json``."""
    return click.option("--json", "as_json", is_flag=True, help=help_text)


def parse_frames(text: str | None) -> tuple[int, int] | None:
    """``"A:B"`` → ``(A, B)`` (frames A .. B-1 of the stage's range)."""
    if text is None:
        return None
    try:
        a, b = (int(x) for x in text.split(":"))
    except ValueError:
        raise click.BadParameter("expected A:B, e.g. 0:100", param_hint="--frames") from None
    if not 0 <= a < b:
        raise click.BadParameter("expected 0 <= A < B", param_hint="--frames")
    return a, b


class FrameProgress:
    """A progress bar (stderr, terminals only) that the library opens through ``on_read`` once
    it knows the frame count and advances through ``progress(done)``; closed on exit."""

    def __init__(self, desc: str, unit: str = "frame") -> None:
        self.desc, self.unit = desc, unit
        self.bar: tqdm | None = None

    def on_read(self, total: int) -> None:
        self.bar = tqdm(total=total, desc=self.desc, unit=self.unit, leave=False, disable=None)

    def progress(self, done: int) -> None:
        if self.bar is not None:
            self.bar.update(done - self.bar.n)

    def __enter__(self) -> FrameProgress:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self.bar is not None:
            self.bar.close()


def parse_betas(text: str | None) -> np.ndarray | None:
    """``--betas``: 1 to 16 comma- or space-separated finite numbers, or None."""
    if text is None:
        return None
    try:
        values = np.asarray([float(x) for x in text.replace(",", " ").split()])
    except ValueError:
        raise click.BadParameter(
            "expected numbers, e.g. '1.5,-0.5'", param_hint="--betas"
        ) from None
    if not 1 <= values.size <= 16 or not np.isfinite(values).all():
        raise click.BadParameter("give 1 to 16 finite values", param_hint="--betas")
    return values
