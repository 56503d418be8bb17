"""``usd-garment motion``: make procedural SMPL motions as playable USD body layers; gather the
poses of many motions into a pose corpus."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click
import numpy as np

from usd_garment.body import NUM_BETAS, load_body_model
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    body_layer_output_option,
    body_model_option,
    collars_option,
)
from usd_garment.motion.pose_corpus import (
    CORPUS_FPS,
    PoseCorpus,
    build_pose_corpus,
    save_pose_corpus,
)
from usd_garment.motion.procedural import (
    ARM_CLEARANCE,
    MOTION_KINDS,
    make_motion,
    random_betas,
)
from usd_garment.usd.body_layer import write_body_layer

USD_SUFFIXES = (".usd", ".usda", ".usdc")
F = TypeVar("F", bound=Callable[..., Any])


@click.group()
def motion() -> None:
    """Procedural motions: list the kinds, make a USD body layer; pose corpora."""


@motion.command("list")
def list_kinds() -> None:
    """The motion kinds and what each does."""
    width = max(len(kind) for kind in MOTION_KINDS)
    for kind, description in MOTION_KINDS.items():
        click.echo(f"{kind:<{width}}  {description}")


def _betas(text: str | None, seed: int) -> np.ndarray | None:
    """``--betas``: up to 10 numbers (comma or space separated), ``random`` for a random shape
    drawn with the motion's seed, or None for the mean shape."""
    if text is None:
        return None
    if text.strip().lower() == "random":
        return random_betas(np.random.default_rng(seed))
    try:
        values = [float(x) for x in text.replace(",", " ").split()]
    except ValueError as exc:
        raise click.BadParameter(f"not a list of numbers: {text!r}", param_hint="--betas") from exc
    if len(values) > NUM_BETAS or not np.isfinite(values).all():
        raise click.BadParameter(f"at most {NUM_BETAS} finite values", param_hint="--betas")
    return np.asarray(values, dtype=np.float32)


@motion.command("make")
@click.argument("kind", type=click.Choice(list(MOTION_KINDS)), metavar="KIND")
@body_layer_output_option
@click.option("--frames", type=click.IntRange(min=1), default=120, show_default=True)
@click.option("--fps", type=click.FloatRange(min=0, min_open=True), default=30.0, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the motion.")
@click.option(
    "--betas",
    default=None,
    help="Body shape: up to 10 numbers ('0.5,-1'), or 'random' (clipped normal, seeded by "
    "--seed). Default: the mean shape.",
)
@click.option(
    "--open-shoulders",
    is_flag=True,
    help=f"Open the shoulders wherever an arm would come within {100 * ARM_CLEARANCE:g} cm of "
    "the torso. Default: arms may hang against the trunk, as in motion capture.",
)
@body_model_option
def make(
    kind: str,
    output: Path,
    frames: int,
    fps: float,
    seed: int,
    betas: str | None,
    open_shoulders: bool,
    body_model: Path | None,
) -> None:
    """Write a procedural motion of KIND as a playable USD body layer (skeleton, animation and
    skinned mesh; Y-up, metres)."""
    if output.suffix.lower() not in USD_SUFFIXES:
        raise click.BadParameter("the output must end in .usda, .usdc or .usd", param_hint="-o")
    shape = _betas(betas, seed)
    with user_errors():
        body = load_body_model(body_model)
        result = make_motion(
            kind, frames, fps, seed=seed, betas=shape, body=body, open_shoulders=open_shoulders
        )
        write_body_layer(output, result, body)
    click.echo(f"wrote {output}: {kind}, {result.num_frames} frames at {result.fps:g} fps")


def corpus_options(command: F) -> F:
    """The options of reading motions' poses (``motion poses``, ``train pose-error``): the
    sampling rate, the BVH shoulders and collars, the body model."""
    for option in reversed((
        click.option("--fps", type=click.FloatRange(min=0, min_open=True), default=CORPUS_FPS,
                     show_default=True, help="Rate each motion is sampled at."),
        click.option("--arm-clearance", type=click.FloatRange(min=0), default=0.0,
                     show_default=True, help="BVH captures: open the shoulders where an arm "
                     "comes closer than this (m) to the torso, as import-bvh does (0: the arms "
                     "as captured; opening them is slow)."),
        collars_option("BVH captures: the collars as import-bvh --collars retargets them."),
        body_model_option,
    )):  # fmt: skip
        command = option(command)
    return command


def read_corpus(
    sources: tuple[Path, ...],
    fps: float,
    arm_clearance: float,
    collars: str,
    body_model: Path | None,
) -> PoseCorpus:
    """The poses of SOURCES as :func:`build_pose_corpus` reads them, with a progress bar;
    ``FileNotFoundError`` names the first source missing."""
    missing = [str(p) for p in sources if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"{missing[0]}: no such file")
    body = load_body_model(body_model)
    with click.progressbar(length=len(sources), label="reading motions") as bar:
        return build_pose_corpus(
            sources, body, fps, arm_clearance or None, collars, progress=lambda _: bar.update(1)
        )


@motion.command("poses")
@click.argument("sources", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
    help="Pose corpus to write (.npz).",
)  # fmt: skip
@corpus_options
def poses(
    sources: tuple[Path, ...],
    output: Path,
    fps: float,
    arm_clearance: float,
    collars: str,
    body_model: Path | None,
) -> None:
    """Gather the body poses of SOURCES (BVH captures, AMASS .npz, USD body layers) into a pose
    corpus that 'train pose' can learn beside the training set's poses (its setting
    pose.corpus): real poses need no simulated garment."""
    if output.suffix.lower() != ".npz":
        raise click.BadParameter("the output must end in .npz", param_hint="-o")
    with user_errors():
        corpus = read_corpus(sources, fps, arm_clearance, collars, body_model)
        save_pose_corpus(output, corpus)
    click.echo(
        f"wrote {output}: {len(corpus.poses)} poses of {len(corpus.sources)} motions at {fps:g} fps"
    )
