"""``usd-garment dress``: write a garment layer for the animated SMPL body of a USD file."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import click

from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    FrameProgress,
    body_model_option,
    frames_option,
    garment_layer_output_option,
    json_option,
    lod_option,
    parse_betas,
    parse_frames,
    skeleton_option,
)
from usd_garment.dress import dress as dress_stage
from usd_garment.garment.template import GARMENT_NAMES
from usd_garment.methods import available_methods, get_method
from usd_garment.methods.budget import pick_for_budget
from usd_garment.methods.learned import (
    LEARNED_METHODS,
    default_method,
    learned_method,
    quality_method,
)

#: The level of detail of each --quality.
QUALITY_LODS = {"draft": "low", "final": "high"}


@click.command("dress")
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@garment_layer_output_option
@click.option(
    "--garment",
    default="tshirt",
    show_default=True,
    help=f"Garment template: {', '.join(GARMENT_NAMES)}.",
)
@click.option(
    "--method",
    default=None,
    help=f"Garment method: {', '.join(available_methods())}. Default: learned+preimage (the "
    "networks' garment pushed out of the body parts that posing carries it into), with the "
    "shipped model of the garment (learned with --quality draft, learned+postprocess with "
    "--quality final; lbs+postprocess for a garment without a model).",
)
@click.option(
    "--model",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Model directory of the learned method (default: the shipped one).",
)
@frames_option
@lod_option
@body_model_option
@skeleton_option
@click.option("--betas", default=None, help="Shape coefficients overriding the stage's.")
@click.option(
    "--cut",
    "cuts",
    type=float,
    multiple=True,
    metavar="TIME",
    help="A time code where the animation starts anew (repeat): an edit's splice too small to "
    "be found, which the garment would otherwise be smoothed across, its dynamics started from "
    "rest there. Added to the skeleton's "
    "smpl:cuts; cuts where the root jumps, or the joints jump in one step that stands out, are "
    "found without it. Times outside the dressed frames cut nothing.",
)
@click.option(
    "--root-layer",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write a layer that sublayers the garment layer and the input.",
)
@click.option(
    "--quality",
    type=click.Choice(tuple(QUALITY_LODS)),
    default=None,
    help="Pick the level of detail for the use: draft (low, and by default the networks' "
    "garment alone: fast previews and layout; a learned model of the high mesh is carried down "
    "to it) or final (high, and by default the learned garment pushed out of the body wherever "
    "the exact inside test finds it: slower); instead of --lod.",
)
@click.option(
    "--error-budget",
    "error_budget",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    metavar="MM",
    help="Pick the fastest method and level of detail whose mean error against the simulation, "
    "measured on held-out motion (the model's budget.json, written by 'usd-garment bench'), is "
    "at most MM millimetres; instead of --method, --lod and --quality.",
)
@click.option(
    "--proxy",
    "proxy_lod",
    type=click.Choice(("medium", "low")),
    default=None,
    help="Also write a decimated proxy-purpose mesh of the garment at this level of detail "
    "(viewports draw it, renders the full one). Its points are carried from the computed "
    "garment, or dressed at that level by the methods that push vertices out of the body "
    "(+postprocess, learned+preimage: carried, their garment can be inside between the vertices "
    "they moved).",
)
@click.option(
    "--lod-variants",
    is_flag=True,
    help="Write the garment as a 'lod' variant set: the computed level of detail (selected) and "
    "each coarser one (carried or dressed, as for --proxy), for a viewer or a pipeline to "
    "switch.",
)
@click.option(
    "--workers",
    type=click.IntRange(1),
    default=1,
    show_default=True,
    help="Processes that push the garment out of the body, one CPU core each; the same garment. "
    "The +postprocess methods (--quality final): the winding-number push-out, ~2 s each to "
    "start, 1.4x faster with 2 workers on a 2-core machine. learned+preimage (the default): "
    "each chunk of 256 frames posed and pushed while this process decodes the next, at most "
    "one worker for every two chunks (on 2 cores with 2 workers: 1.1-1.3x on a 4,000-frame "
    "shot, 1.04-1.23x on 1,000 frames, about twice the memory; docs/learning.md).",
)
@json_option()
def dress(
    input_path: Path,
    output: Path,
    garment: str,
    method: str | None,
    model: Path | None,
    frames: str | None,
    lod: str,
    body_model: Path | None,
    skeleton: str | None,
    betas: str | None,
    cuts: tuple[float, ...],
    root_layer: Path | None,
    quality: str | None,
    error_budget: float | None,
    proxy_lod: str | None,
    lod_variants: bool,
    workers: int,
    as_json: bool,
) -> None:
    """Dress the animated SMPL body of INPUT; write the garment layer to OUTPUT."""
    frame_range, beta_values = parse_frames(frames), parse_betas(betas)
    picked = None
    if error_budget is not None:
        context = click.get_current_context()
        for name in ("lod", "quality", "method"):
            if context.get_parameter_source(name) is not click.core.ParameterSource.DEFAULT:
                raise click.BadParameter(
                    f"give --error-budget or --{name}, not both", param_hint="--error-budget"
                )
        with user_errors():
            picked = pick_for_budget(garment, model, error_budget)
        method, lod = picked.method, picked.lod
        if method not in LEARNED_METHODS:
            model = None  # the model directory only held the table
    if quality is not None:
        source = click.get_current_context().get_parameter_source("lod")
        if source is not click.core.ParameterSource.DEFAULT:
            raise click.BadParameter("give --quality or --lod, not both", param_hint="--quality")
        lod = QUALITY_LODS[quality]
    if method is None:
        shipped = model is None  # a model directory given: its learned method of the quality
        method = default_method(garment, lod, quality) if shipped else quality_method(quality)
    if model is not None and method not in LEARNED_METHODS:
        raise click.BadParameter(
            f"a model directory is for --method {' or '.join(LEARNED_METHODS)}",
            param_hint="--model",
        )
    with user_errors():
        learned = method in LEARNED_METHODS
        instance = learned_method(method, model) if learned else get_method(method)
    if workers > 1:
        if getattr(instance, "push_out", False):
            instance.push_out_workers = workers
        elif getattr(instance, "preimage", False):
            instance.workers = workers
        else:
            raise click.BadParameter(
                f"{method} pushes nothing out of the body to spread over processes: --workers "
                "is for learned+preimage (the default), the +postprocess methods and --quality "
                "final",
                param_hint="--workers",
            )
    with FrameProgress(method) as bar, user_errors():
        result = dress_stage(
            input_path,
            output,
            garment=garment,
            method=instance,
            frames=frame_range,
            lod=lod,
            body_model=body_model,
            skeleton=skeleton,
            betas=beta_values,
            cuts=cuts,
            root_layer=root_layer,
            proxy_lod=proxy_lod,
            lod_variants=lod_variants,
            on_read=bar.on_read,
            progress=bar.progress,
        )
    if as_json:
        out = result.to_json()
        if picked is not None:
            out["error_budget"] = {"budget_mm": error_budget, **asdict(picked)}
        click.echo(json.dumps(out, indent=2))
        return
    if picked is not None:
        click.echo(
            f"error budget {error_budget:g} mm: {picked.method} at {picked.lod} "
            f"({picked.error_mm:.1f} mm on held-out motion, {picked.frames_per_second:.0f} "
            "frames/s on the bench)"
        )
    s = result.seconds
    click.echo(
        f"{result.garment} ({result.method}): {result.frames} frames × {result.vertices} vertices "
        f"in {sum(s.values()):.2f} s (read {s['read']:.2f}, compute {s['compute']:.2f}, "
        f"write {s['write']:.2f})"
    )
    restarts = [t for t in result.cuts if t not in result.root_jumps]
    if restarts:
        click.echo(f"starts anew at time codes {', '.join(f'{t:g}' for t in restarts)}")
    if result.root_jumps:
        jumps = ", ".join(f"{t:g}" for t in result.root_jumps)
        click.echo(f"the root alone jumps at time codes {jumps} (one motion going on, moved)")
    for path in result.outputs:
        click.echo(f"wrote {path}")
