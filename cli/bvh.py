"""``usd-garment import-bvh``: BVH (CMU, Mixamo) and ASF/AMC motion captures retargeted to USD body
layers."""

from __future__ import annotations

import json
from pathlib import Path

import click

from usd_garment.body import load_body_model
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import (
    body_layer_output_option,
    body_model_option,
    collars_option,
    json_option,
    parse_betas,
    parse_frames,
    resample_fps_option,
)
from usd_garment.motion.bvh import ARM_CONTACT_CLEARANCE, FLOOR_MODES, UNITS, UP_AXES, load_bvh
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.garment_layer import check_outputs


@click.command("import-bvh")
@click.argument("bvh", type=click.Path(dir_okay=False, path_type=Path))
@body_layer_output_option
@resample_fps_option
@click.option(
    "--units", type=click.Choice(["auto", *UNITS]), default="auto", show_default=True,
    help="Length unit of the file; auto tells m, cm and mm apart by the skeleton's height.",
)  # fmt: skip
@click.option(
    "--scale", type=click.FloatRange(min=0, min_open=True), default=None,
    help="Metres per file unit (overrides --units).",
)  # fmt: skip
@click.option(
    "--up-axis", type=click.Choice(UP_AXES), default="auto", show_default=True,
    help="Up axis of the file; auto: the axis from the hips to the head in the rest pose.",
)  # fmt: skip
@click.option(
    "--floor", type=click.Choice(FLOOR_MODES), default="body", show_default=True,
    help="body: move the clip so the body stands on y=0; capture: keep the capture's heights.",
)  # fmt: skip
@click.option(
    "--frames",
    default=None,
    help="Frames A:B of the file (B exclusive). Default: all, less frame 0 where it is a "
    "reference pose that the motion leaves at once (the T-pose of CMU's BVH conversions).",
)
@click.option(
    "--arm-clearance", type=click.FloatRange(min=0), default=ARM_CONTACT_CLEARANCE,
    show_default=True,
    help="Open the shoulders where an arm comes closer than this (m) to the torso, so that the "
    "arms rest against the trunk instead of passing through it (0: off).",
)  # fmt: skip
@click.option(
    "--no-arm-correction", is_flag=True,
    help="Keep the captured bone directions of the arms (same as --arm-clearance 0).",
)  # fmt: skip
@collars_option(
    "rest: the collars turn from the body's rest collars (the shipped models' training); "
    "aimed: the collar bones along the capture's (CMU captures come out shrugged, as the "
    "T-shirt's version 7 and the dress's version 9 were trained; docs/mocap.md)."
)
@click.option("--betas", default=None, help="Shape coefficients of the body (default zero).")
@body_model_option
@click.option("--no-mesh", is_flag=True, help="Write the skeleton only, without the body mesh.")
@json_option("Print the joint mapping, units, floor shift and shoulder opening as JSON on stdout.")
def import_bvh(
    bvh: Path,
    output: Path,
    fps: float | None,
    units: str,
    scale: float | None,
    up_axis: str,
    floor: str,
    frames: str | None,
    arm_clearance: float,
    no_arm_correction: bool,
    collars: str,
    betas: str | None,
    body_model: Path | None,
    no_mesh: bool,
    as_json: bool,
) -> None:
    """Retarget a BVH motion capture (CMU, Mixamo or SMPL joint names; .bvh, or compressed
    .bvh.xz / .bvh.gz) to the SMPL skeleton and write it as a USD body layer (Y-up, metres).

    Also reads ASF/AMC captures (the CMU database's own format: .amc, .amc.xz, .amc.gz, with
    SUBJECT.asf or the folder's only .asf beside SUBJECT_TRIAL.amc), at 120 fps."""
    frame_range, beta_values = parse_frames(frames), parse_betas(betas)
    with user_errors():
        if not bvh.is_file():
            raise FileNotFoundError(f"{bvh}: no such file")
        check_outputs(bvh, output)
        body = load_body_model(body_model)
        motion, info = load_bvh(
            bvh, body, fps, beta_values, units=units, scale=scale, up_axis=up_axis,
            floor=floor, frames=frame_range,
            arm_clearance=None if no_arm_correction else arm_clearance, collars=collars,
        )  # fmt: skip
        write_body_layer(output, motion, body, with_mesh=not no_mesh)
    if as_json:
        summary = {
            "output": str(output),
            "frames": motion.num_frames,
            "fps": motion.fps,
            "source_fps": info.source_fps,
            "units": info.units,
            "units_detected": info.units_detected,
            "metres_per_unit": info.scale,
            "skeleton_height_m": round(info.height_m, 4),
            "up_axis": info.up_axis,
            "floor": info.floor,
            "floor_shift_m": round(info.floor_shift_m, 4),
            "arm_clearance_m": info.arm_clearance_m,
            "collars": collars,
            "shoulder_opening": info.opening_summary(),
            "reference_left_out": info.reference_left_out,
            "joint_map": info.joint_map,
            "drivers": {k: v for k, v in info.drivers.items() if v != info.joint_map[k]},
            "unmapped": info.unmapped,
            "folded": info.folded,
            "ignored": info.ignored,
        }
        click.echo(json.dumps(summary, indent=2))
        return
    opened = ""
    if info.arm_clearance_m is not None:
        summary = info.opening_summary()
        opened = (
            f"; shoulders opened up to {summary['max_deg']:.1f}° (mean {summary['mean_deg']:.1f}°, "
            f"{summary['frames']} frames) to keep {1000 * info.arm_clearance_m:g} mm clear"
        )
    if info.reference_left_out:
        opened += (
            "; frame 0 left out: a reference pose the motion leaves at once (--frames keeps it)"
        )
    unit = f"{info.units}{' (detected)' if info.units_detected else ''}"
    click.echo(
        f"wrote {output}: {motion.num_frames} frames at {motion.fps:g} fps; units {unit}, "
        f"skeleton {info.height_m:.2f} m tall, {len(info.joint_map)}/24 SMPL joints mapped, "
        f"floor shift {info.floor_shift_m:+.3f} m{opened}"
    )
