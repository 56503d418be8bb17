"""Fitting the diffused body fields and the canonical SDF of a body model (the library call of
``usd-garment fields fit``): sample points around the rest body, compute the paper's diffusion
targets, fit the MLPs, bake them into grids; sample the exact signed distance on grids.

Needs Warp (the ``[train]`` extra) for the closest-point queries.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numpy as np
import torch

from usd_garment.body.joints import NUM_BETAS
from usd_garment.body.model import BodyModel
from usd_garment.fields.body_fields import BodyFields
from usd_garment.fields.diffusion import BodySurfaceQuery
from usd_garment.fields.grid import DenseGrid, SparseGrid
from usd_garment.fields.mlp import FieldMLP, train_field

#: ``progress(stage, done, total)``: absolute progress within a named stage.
Progress = Callable[[str, int, int], None]


@dataclass
class FitConfig:
    """Settings of a fit; stored in the fields file and next to it as JSON.

    Attributes:
        samples: training points around the rest body.
        diffusion_samples: N, Gaussian samples averaged per training point.
        epochs: passes over the training points per MLP.
        seed: seed of every random draw.
        surface_share / near_share: shares of training points on the surface and within a few
            centimetres of it (normal offsets, exponential with scale ``near_scale``); the rest
            is uniform in the box.
        margin: the grids' box is the body's bounding box grown by this (m).
        field_spacings / field_bands: spacing (m) of each sparse field grid level, finest first,
            and its band: nodes inside the body or at most this far outside (m).
        coarse_field_spacing: spacing of the dense field grid used beyond the bands (m).
        weight_floor: baked skinning weights below this are set to 0 (then renormalised), so
            the stored grids compress well.
        sdf_spacing / sdf_band: fine SDF grid spacing (m) and band half-width (m).
        sdf_coarse_spacing: spacing of the dense SDF grid over the box (m).
    """

    samples: int = 60_000
    diffusion_samples: int = 256
    epochs: int = 8
    seed: int = 0
    surface_share: float = 0.25
    near_share: float = 0.5
    near_scale: float = 0.04
    margin: float = 0.3
    field_spacings: tuple[float, ...] = (0.02, 0.05)
    field_bands: tuple[float, ...] = (0.05, 0.3)
    coarse_field_spacing: float = 0.15
    weight_floor: float = 5e-4
    sdf_spacing: float = 0.005
    sdf_band: float = 0.03
    sdf_coarse_spacing: float = 0.02
    batch: int = 2048
    lr: float = 2e-3


def _lattice(lower: np.ndarray, upper: np.ndarray, spacing: float) -> tuple[np.ndarray, tuple]:
    """Node positions ``(nx·ny·nz, 3)`` (C-order) and the shape of a lattice covering a box."""
    shape = tuple(
        int(np.ceil((hi - lo) / spacing)) + 1 for lo, hi in zip(lower, upper, strict=True)
    )
    axes = [lower[i] + spacing * np.arange(shape[i]) for i in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return nodes.astype(np.float32), shape


def _dilate(mask: np.ndarray) -> np.ndarray:
    """Grow a 3D bool mask by one node along every axis and diagonal (3×3×3 neighbourhood)."""
    out = mask.copy()
    padded = np.pad(mask, 1)
    for dx in range(3):
        for dy in range(3):
            for dz in range(3):
                out |= padded[
                    dx : dx + mask.shape[0], dy : dy + mask.shape[1], dz : dz + mask.shape[2]
                ]
    return out


def sample_training_points(
    vertices: np.ndarray, faces: np.ndarray, config: FitConfig, rng: np.random.Generator
) -> np.ndarray:
    """Training points ``(samples, 3)`` (m): on the surface, offset along the face normal by an
    exponential distance (inside or outside), and uniform in the grids' box."""
    tri = vertices[faces]  # (F, 3, 3)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(area, 1e-12)[:, None]
    n_surface = int(config.samples * config.surface_share)
    n_near = int(config.samples * config.near_share)
    n_box = config.samples - n_surface - n_near
    n_on = n_surface + n_near
    face = rng.choice(len(faces), size=n_on, p=area / area.sum())
    r = rng.random((n_on, 2))
    flip = r.sum(1) > 1
    r[flip] = 1 - r[flip]
    bary = np.stack([1 - r.sum(1), r[:, 0], r[:, 1]], axis=1)
    on = np.einsum("mk,mkc->mc", bary, tri[face])
    offset = rng.exponential(config.near_scale, size=n_on) * np.where(
        rng.random(n_on) < 0.7, 1.0, -1.0
    )
    offset[:n_surface] = 0.0
    near = on + offset[:, None] * normal[face]
    lower = vertices.min(0) - config.margin
    upper = vertices.max(0) + config.margin
    box = lower + (upper - lower) * rng.random((n_box, 3))
    return np.concatenate([near, box]).astype(np.float32)


def _bake_fields(
    mlps: dict[str, FieldMLP], nodes: np.ndarray, weight_floor: float
) -> dict[str, torch.Tensor]:
    """MLP values at grid nodes ``(M, 3)``: name → ``(M, C)``; tiny weights zeroed."""
    x = torch.from_numpy(nodes)
    values = {name: mlp.evaluate(x) for name, mlp in mlps.items()}
    w = values["weights"] * (values["weights"] >= weight_floor)
    values["weights"] = w / w.sum(-1, keepdim=True)
    return values


def _mlp_state(mlps: dict[str, FieldMLP]) -> dict[str, np.ndarray]:
    return {
        f"{name}/{key}": value.numpy()
        for name, mlp in mlps.items()
        for key, value in mlp.state_dict().items()
    }


def fit_body_fields(
    body: BodyModel,
    *,
    config: FitConfig | None = None,
    samples: int | None = None,
    diffusion_samples: int | None = None,
    epochs: int | None = None,
    seed: int | None = None,
    progress: Progress | None = None,
) -> BodyFields:
    """Fit the diffused fields and the canonical SDF of ``body`` at β = 0 in its T-pose.

    The blendshape fields output per-point matrices (3 × 10, and 3 × 207 when the body has pose
    blendshapes) rather than taking β or θ as input: blendshapes are linear in β and in the pose
    features, so the diffused field of the matrix is exactly the diffused offset divided out,
    and one evaluation serves every shape and frame.

    ``samples``, ``diffusion_samples``, ``epochs`` and ``seed`` override ``config``'s (default
    :class:`FitConfig`). ``progress(stage, done, total)`` reports each stage.
    """
    given = {"samples": samples, "diffusion_samples": diffusion_samples, "epochs": epochs}
    given["seed"] = seed
    config = replace(config or FitConfig(), **{k: v for k, v in given.items() if v is not None})
    report = progress or (lambda stage, done, total: None)
    rng = np.random.default_rng(config.seed)
    torch.manual_seed(config.seed)
    timings: dict[str, float] = {}
    vertices = body.v_template.detach().cpu().numpy().astype(np.float32)
    faces = body.faces.detach().cpu().numpy()
    query = BodySurfaceQuery(vertices, faces)
    lower = vertices.min(0) - config.margin
    upper = vertices.max(0) + config.margin

    # Diffusion targets at the training points.
    t0 = time.perf_counter()
    points = sample_training_points(vertices, faces, config, rng)
    done = [0]

    def _diffusion_progress(n: int) -> None:
        done[0] += n
        report("diffusion targets", done[0], len(points))

    diffuse = query.diffusion_matrix(points, config.diffusion_samples, rng, _diffusion_progress)
    values = {
        "weights": body.weights.detach().cpu().numpy(),
        "shape_dirs": body.shapedirs.detach().cpu().numpy().reshape(len(vertices), -1),
    }
    if body.has_pose_blendshapes:
        values["pose_dirs"] = body.posedirs.detach().cpu().numpy().reshape(len(vertices), -1)
    targets = {name: (diffuse @ v).astype(np.float32) for name, v in values.items()}
    timings["diffusion_s"] = time.perf_counter() - t0

    # MLPs.
    t0 = time.perf_counter()
    center = torch.from_numpy((lower + upper) / 2)
    scale = float((upper - lower).max() / 2)
    mlps: dict[str, FieldMLP] = {}
    losses: dict[str, float] = {}
    steps = config.epochs * max(1, len(points) // config.batch)
    for name, target in targets.items():
        spread = torch.from_numpy(np.maximum(target.std(0), 1e-6))
        mlp = FieldMLP(target.shape[1], name == "weights", center, scale, spread)
        step = [0]

        def _train_progress(n: int, name: str = name, step: list[int] = step) -> None:
            step[0] += n
            report(f"fitting {name}", step[0], steps)

        losses[name] = train_field(
            mlp,
            points,
            target,
            epochs=config.epochs,
            batch=config.batch,
            lr=config.lr,
            seed=config.seed,
            progress=_train_progress,
        )
        mlps[name] = mlp.eval()
    timings["training_s"] = time.perf_counter() - t0

    # Canonical SDF: exact on a coarse dense lattice, then a fine band near the surface.
    t0 = time.perf_counter()
    report("signed distance", 0, 2)
    coarse_nodes, coarse_shape = _lattice(lower, upper, config.sdf_coarse_spacing)
    coarse_sdf = query.signed_distance(coarse_nodes)
    sdf_coarse = DenseGrid(
        torch.from_numpy(lower),
        config.sdf_coarse_spacing,
        {"sdf": torch.from_numpy(coarse_sdf).reshape(*coarse_shape, 1)},
    )
    report("signed distance", 1, 2)
    fine_lower = vertices.min(0) - config.sdf_band - 2 * config.sdf_spacing
    fine_upper = vertices.max(0) + config.sdf_band + 2 * config.sdf_spacing
    fine_nodes, fine_shape = _lattice(fine_lower, fine_upper, config.sdf_spacing)
    (approx,) = sdf_coarse(torch.from_numpy(fine_nodes), ("sdf",))
    reach = config.sdf_band + config.sdf_coarse_spacing * np.sqrt(3)
    candidate = np.abs(approx[:, 0].numpy()) < reach
    exact = np.full(len(fine_nodes), np.inf, dtype=np.float32)
    exact[candidate] = query.signed_distance(fine_nodes[candidate])
    band = _dilate((np.abs(exact) < config.sdf_band).reshape(fine_shape)) & candidate.reshape(
        fine_shape
    )
    sdf_fine = SparseGrid(
        torch.from_numpy(fine_lower),
        config.sdf_spacing,
        torch.from_numpy(band),
        {"sdf": torch.from_numpy(exact[band.reshape(-1)])[:, None]},
    )
    report("signed distance", 2, 2)
    timings["sdf_s"] = time.perf_counter() - t0

    # Bake the fields: a fine band (inside, and up to field_band outside) and a coarse box.
    t0 = time.perf_counter()
    levels = []
    for spacing, band in zip(config.field_spacings, config.field_bands, strict=True):
        nodes, shape = _lattice(lower, upper, spacing)
        (node_sdf,) = sdf_coarse(torch.from_numpy(nodes), ("sdf",))
        mask = _dilate((node_sdf[:, 0].numpy() < band).reshape(shape))
        baked = _bake_fields(mlps, nodes[mask.reshape(-1)], config.weight_floor)
        levels.append(SparseGrid(torch.from_numpy(lower), spacing, torch.from_numpy(mask), baked))
    box_nodes, box_shape = _lattice(lower, upper, config.coarse_field_spacing)
    fields_coarse = DenseGrid(
        torch.from_numpy(lower),
        config.coarse_field_spacing,
        {
            k: v.reshape(*box_shape, -1)
            for k, v in _bake_fields(mlps, box_nodes, config.weight_floor).items()
        },
    )
    timings["bake_s"] = time.perf_counter() - t0

    meta = {
        **asdict(config),
        "diffusion_std": "d (the distance to the surface)",
        "body": body.name,
        "num_betas": NUM_BETAS,
        "final_losses": losses,
        "timings_s": {k: round(v, 1) for k, v in timings.items()},
    }
    return BodyFields(
        levels, fields_coarse, sdf_fine, sdf_coarse, body.name, meta, _mlp_state(mlps)
    )


def mlps_from_state(state: dict[str, np.ndarray]) -> dict[str, FieldMLP]:
    """Rebuild the fitted MLPs (name → :class:`FieldMLP`) from a fields file's ``mlp_state``."""
    mlps: dict[str, FieldMLP] = {}
    for name in sorted({k.split("/", 1)[0] for k in state}):
        sub = {k.split("/", 1)[1]: torch.from_numpy(v) for k, v in state.items()
               if k.startswith(name + "/")}  # fmt: skip
        channels = sub["out_scale"].shape[0]
        mlp = FieldMLP(channels, name == "weights")
        mlp.load_state_dict(sub)
        mlps[name] = mlp.eval()
    return mlps
