"""``usd-garment simulate``: simulate a garment on the animated SMPL body of a USD file with the
cloth simulator and write the garment layer (GarmentAPI method "simulation")."""

from __future__ import annotations

import json
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
    parse_frames,
    skeleton_option,
    solver_options,
)
from usd_garment.dress import dress as dress_stage
from usd_garment.garment.template import GARMENT_NAMES
from usd_garment.methods.simulation import SimulationMethod
from usd_garment.sim.cloth import MAX_BAD_RUN, MAX_SUBSTEPS, RELEASE_MODES, ContactSettings
from usd_garment.sim.material import ClothMaterial


@click.command("simulate")
@click.argument("input_path", metavar="BODY", type=click.Path(path_type=Path))
@garment_layer_output_option
@click.option("--garment", type=click.Choice(GARMENT_NAMES), default="tshirt", show_default=True)
@lod_option
@solver_options
@frames_option
@body_model_option
@skeleton_option
@click.option(
    "--strict",
    is_flag=True,
    help="Fail at the first frame that fails its checks with the most substeps (default: keep "
    "it, flagged in the per-frame quality; NaN, a garment that fell off or more than "
    f"{MAX_BAD_RUN} bad frames in a row fail anyway).",
)
@click.option(
    "--release",
    type=click.Choice(RELEASE_MODES),
    default=ContactSettings().release,
    show_default=True,
    help="When the garment's torso panels ignore the arms' skin (the end-of-frame projection "
    "still keeps them out of an arm): never; on one last try of a frame that fails its checks "
    "with the most substeps; or always. An arm pressed into the trunk, as captures hold it, "
    "otherwise catches the hem in the hip.",
)
@json_option()
def simulate(
    input_path: Path,
    output: Path,
    garment: str,
    lod: str,
    substeps: int,
    iterations: int,
    material: Path | None,
    frames: str | None,
    body_model: Path | None,
    skeleton: str | None,
    strict: bool,
    release: str,
    as_json: bool,
) -> None:
    """Simulate a garment on the animated SMPL body of BODY; write the garment layer."""
    frame_range = parse_frames(frames)
    with FrameProgress("simulation") as bar, user_errors():
        fabric = ClothMaterial.load(material) if material is not None else None
        method = SimulationMethod(
            substeps,
            iterations,
            fabric,
            max_substeps=max(MAX_SUBSTEPS, substeps),
            strict=strict,
            contact=ContactSettings(release=release),
        )
        result = dress_stage(
            input_path,
            output,
            garment=garment,
            method=method,
            frames=frame_range,
            lod=lod,
            body_model=body_model,
            skeleton=skeleton,
            on_read=bar.on_read,
            progress=bar.progress,
        )
    settings = method.settings
    if as_json:
        click.echo(json.dumps({**result.to_json(), "simulation": settings}, indent=2))
        return
    s = result.seconds
    click.echo(
        f"{result.garment} (simulation): {result.frames} frames × {result.vertices} vertices in "
        f"{sum(s.values()):.1f} s ({settings['seconds_per_frame']:.2f} s/frame simulated); "
        f"inside the body where the pose forces it mean "
        f"{100 * settings['inside_forced_share_mean']:.3f}%, elsewhere mean "
        f"{100 * settings['inside_elsewhere_share_mean']:.3f}% (max "
        f"{100 * settings['inside_elsewhere_share_max']:.3f}%), max distance "
        f"{settings['max_distance_m']:.3f} m, stretch p99 max {settings['stretch_p99_max']:.3f} "
        f"(largest edge {settings['stretch_max']:.2f}), "
        f"{len(settings['retries'])} frames retried, {settings['released_frames']} released "
        f"from the arms, {settings['bad_frames']} bad frames kept"
    )
    for path in result.outputs:
        click.echo(f"wrote {path}")
