"""``usd-garment dress``: write a garment layer for the animated SMPL body of a USD file."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from usd_garment.cli.errors import user_errors
from usd_garment.dress import dress as dress_stage
from usd_garment.garment.template import GARMENT_NAMES, LODS
from usd_garment.methods import available_methods


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


def parse_betas(text: str | None) -> np.ndarray | None:
    """Up to 16 comma- or space-separated floats, or None."""
    if text is None:
        return None
    try:
        values = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise click.BadParameter(
            "expected numbers, e.g. '1.5,-0.5'", param_hint="--betas"
        ) from None
    if not values or len(values) > 16:
        raise click.BadParameter("give 1 to 16 values", param_hint="--betas")
    return np.asarray(values, dtype=np.float64)


@click.command("dress")
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Garment layer to write (.usdc, .usd or .usda).",
)
@click.option(
    "--garment",
    default="tshirt",
    show_default=True,
    help=f"Garment template: {', '.join(GARMENT_NAMES)}.",
)
@click.option(
    "--method",
    default="lbs",
    show_default=True,
    help=f"Garment method: {', '.join(available_methods())}.",
)
@click.option("--frames", default=None, help="Frames A:B of the stage's range (B exclusive).")
@click.option("--lod", type=click.Choice(tuple(LODS)), default="high", show_default=True)
@click.option(
    "--body-model",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="SMPL-layout body file (.npz/.pkl); default: the embedded free body.",
)
@click.option("--skeleton", default=None, help="Skeleton prim path when the stage has several.")
@click.option("--betas", default=None, help="Shape coefficients overriding the stage's.")
@click.option(
    "--root-layer",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write a layer that sublayers the garment layer and the input.",
)
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary on stdout.")
def dress(
    input_path: Path,
    output: Path,
    garment: str,
    method: str,
    frames: str | None,
    lod: str,
    body_model: Path | None,
    skeleton: str | None,
    betas: str | None,
    root_layer: Path | None,
    as_json: bool,
) -> None:
    """Dress the animated SMPL body of INPUT; write the garment layer to OUTPUT."""
    frame_range, beta_values = parse_frames(frames), parse_betas(betas)
    bar: tqdm | None = None

    def on_read(total: int) -> None:
        nonlocal bar
        bar = tqdm(total=total, desc=method, unit="frame", leave=False, disable=None)

    def progress(done: int) -> None:
        if bar is not None:
            bar.update(done - bar.n)

    try:
        with user_errors():
            result = dress_stage(
                input_path,
                output,
                garment=garment,
                method=method,
                frames=frame_range,
                lod=lod,
                body_model=body_model,
                skeleton=skeleton,
                betas=beta_values,
                root_layer=root_layer,
                on_read=on_read,
                progress=progress,
            )
    finally:
        if bar is not None:
            bar.close()
    if as_json:
        click.echo(json.dumps(result.to_json(), indent=2))
        return
    s = result.seconds
    click.echo(
        f"{result.garment} ({result.method}): {result.frames} frames × {result.vertices} vertices "
        f"in {sum(s.values()):.2f} s (read {s['read']:.2f}, compute {s['compute']:.2f}, "
        f"write {s['write']:.2f})"
    )
    for path in result.outputs:
        click.echo(f"wrote {path}")
