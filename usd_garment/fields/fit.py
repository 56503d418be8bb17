"""Fitting the diffused body fields and the canonical SDF of a body model (the library call of
``usd-garment fields fit``): sample the exact signed distance on grids, then fill the field grids
with the paper's diffused values, either computed directly at the grid nodes (``direct``) or
through MLPs fitted to diffusion targets at sampled points (``mlp``, as in the paper).

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
#: How the field grids are filled: the diffusion at the nodes, or MLPs fitted to it.
METHODS = ("direct", "mlp")
#: Settings that only the ``mlp`` method uses (left out of a direct fit's stored settings).
MLP_SETTINGS = ("samples", "epochs", "surface_share", "near_share", "near_scale", "batch", "lr")


@dataclass(frozen=True)
class FieldLevel:
    """One sparse level of the field grids.

    Attributes:
        spacing: node spacing (m).
        outside: the level's band holds the nodes at most this far outside the body (m) ...
        inside: ... and at most this far inside it (m); None: every node inside.
        groups: the field groups it holds (of ``weights``, ``shape_dirs``, ``pose_dirs``; groups
            the body lacks are skipped).
    """

    spacing: float
    outside: float
    inside: float | None = None
    groups: tuple[str, ...] = ("weights", "shape_dirs", "pose_dirs")


#: Blendshape groups (smooth: they can live on coarser levels than the skinning weights).
BLENDSHAPES = ("shape_dirs", "pose_dirs")


@dataclass
class FitConfig:
    """Settings of a fit; stored in the fields file and next to it as JSON.

    Attributes:
        method: ``direct`` (diffusion computed at every grid node) or ``mlp``.
        diffusion_samples: N, Gaussian samples averaged per point.
        seed: seed of every random draw.
        margin: the grids' box is the body's bounding box grown by this (m).
        levels: the sparse field levels, finest first for each group; by default the skinning
            weights (which vary fastest) get a 7.5 mm band within 2 cm of the surface, the
            blendshapes a 3 cm grid.
        coarse_field_spacing: spacing of the dense field grid used beyond the bands (m).
        weight_floor: baked skinning weights below this are set to 0 (then renormalised), so
            the stored grids compress well.
        sdf_spacing / sdf_band: fine SDF grid spacing (m) and band half-width (m).
        sdf_coarse_spacing: spacing of the dense SDF grid over the box (m).
        samples, epochs, batch, lr: ``mlp`` only: training points, epochs per MLP, batch size
            and learning rate.
        surface_share / near_share / near_scale: ``mlp`` only: shares of training points on the
            surface and within a few centimetres of it (normal offsets, exponential with scale
            ``near_scale``); the rest is uniform in the box.
    """

    method: str = "direct"
    diffusion_samples: int = 256
    seed: int = 0
    margin: float = 0.3
    levels: tuple[FieldLevel, ...] = (
        FieldLevel(0.0075, outside=0.02, inside=0.02, groups=("weights",)),
        FieldLevel(0.02, outside=0.05, groups=("weights",)),
        FieldLevel(0.03, outside=0.06, groups=BLENDSHAPES),
        FieldLevel(0.05, outside=0.3),
    )
    coarse_field_spacing: float = 0.15
    weight_floor: float = 5e-4
    sdf_spacing: float = 0.005
    sdf_band: float = 0.03
    sdf_coarse_spacing: float = 0.02
    samples: int = 60_000
    epochs: int = 8
    batch: int = 2048
    lr: float = 2e-3
    surface_share: float = 0.25
    near_share: float = 0.5
    near_scale: float = 0.04


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


def _surface_band(
    query: BodySurfaceQuery,
    sdf_coarse: DenseGrid,
    spacing: float,
    outside: float,
    inside: float | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A lattice of ``spacing`` (m) around the body and its nodes at most ``outside`` (m) outside
    and ``inside`` (m; None: any depth) inside the surface, grown by one node: origin ``(3,)``,
    mask ``(nx, ny, nz)``, masked node positions ``(B, 3)`` and their exact signed distances
    ``(B,)`` (m)."""
    lower = query.vertices.min(0) - outside - 2 * spacing
    upper = query.vertices.max(0) + outside + 2 * spacing
    nodes, shape = _lattice(lower, upper, spacing)
    (approx,) = sdf_coarse(torch.from_numpy(nodes), ("sdf",))
    approx = approx[:, 0].numpy()
    reach = (spacing + sdf_coarse.spacing) * np.sqrt(3)  # the SDF is 1-Lipschitz
    depth = np.inf if inside is None else inside
    candidate = (approx < outside + reach) & (approx > -depth - reach)
    exact = np.full(len(nodes), np.inf, dtype=np.float32)
    exact[candidate] = query.signed_distance(nodes[candidate])
    band = (exact < outside) & (exact > -depth)
    mask = _dilate(band.reshape(shape)) & candidate.reshape(shape)
    flat = mask.reshape(-1)
    return lower, mask, nodes[flat], exact[flat]


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


def _floor_weights(weights: torch.Tensor, floor: float) -> torch.Tensor:
    """Skinning weights ``(M, 24)`` with entries below ``floor`` zeroed, renormalised."""
    w = weights * (weights >= floor)
    return w / w.sum(-1, keepdim=True)


def _mlp_state(mlps: dict[str, FieldMLP]) -> dict[str, np.ndarray]:
    return {
        f"{name}/{key}": value.numpy()
        for name, mlp in mlps.items()
        for key, value in mlp.state_dict().items()
    }


def _fit_mlps(
    query: BodySurfaceQuery,
    surface: dict[str, np.ndarray],
    config: FitConfig,
    rng: np.random.Generator,
    report: Progress,
) -> tuple[dict[str, FieldMLP], dict[str, float]]:
    """One MLP per field group, fitted to the diffusion targets at sampled training points, and
    each one's mean loss over its last epoch."""
    points = sample_training_points(query.vertices, query.faces, config, rng)
    stacked = np.concatenate(list(surface.values()), axis=1)
    done = [0]

    def _diffusion_progress(n: int) -> None:
        done[0] += n
        report("diffusion targets", done[0], len(points))

    diffused = query.diffuse(points, stacked, config.diffusion_samples, rng, _diffusion_progress)
    split = np.cumsum([v.shape[1] for v in surface.values()])[:-1]
    targets = dict(zip(surface, np.split(diffused, split, axis=1), strict=True))
    lower = query.vertices.min(0) - config.margin
    upper = query.vertices.max(0) + config.margin
    center = torch.from_numpy((lower + upper) / 2)
    scale = float((upper - lower).max() / 2)
    steps = config.epochs * max(1, len(points) // config.batch)
    mlps: dict[str, FieldMLP] = {}
    losses: dict[str, float] = {}
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
    return mlps, losses


def fit_body_fields(
    body: BodyModel,
    *,
    config: FitConfig | None = None,
    method: str | None = None,
    samples: int | None = None,
    diffusion_samples: int | None = None,
    epochs: int | None = None,
    seed: int | None = None,
    progress: Progress | None = None,
) -> BodyFields:
    """Fit the diffused fields and the canonical SDF of ``body`` at β = 0 in its T-pose.

    ``direct`` computes the paper's diffused values at every grid node (so the grids hold the
    diffused field up to trilinear interpolation); ``mlp`` fits the paper's MLPs to diffusion
    targets at sampled points and bakes them into the same grids (keeping their state).

    The blendshape fields are per-point matrices (3 × 10, and 3 × 207 when the body has pose
    blendshapes) rather than functions of β or θ: blendshapes are linear in β and in the pose
    features, so the diffused field of the matrix is exactly the diffused offset divided out,
    and one evaluation serves every shape and frame.

    ``method``, ``samples``, ``diffusion_samples``, ``epochs`` and ``seed`` override
    ``config``'s (default :class:`FitConfig`). ``progress(stage, done, total)`` reports each
    stage.

    Raises:
        ValueError: unknown method.
    """
    given = {"method": method, "samples": samples, "diffusion_samples": diffusion_samples}
    given |= {"epochs": epochs, "seed": seed}
    config = replace(config or FitConfig(), **{k: v for k, v in given.items() if v is not None})
    if config.method not in METHODS:
        raise ValueError(f"unknown fitting method {config.method!r} (one of {', '.join(METHODS)})")
    report = progress or (lambda stage, done, total: None)
    rng = np.random.default_rng(config.seed)
    torch.manual_seed(config.seed)
    timings: dict[str, float] = {}
    vertices = body.v_template.detach().cpu().numpy().astype(np.float32)
    query = BodySurfaceQuery(vertices, body.faces.detach().cpu().numpy())
    lower = vertices.min(0) - config.margin
    upper = vertices.max(0) + config.margin
    surface = {
        "weights": body.weights.detach().cpu().numpy(),
        "shape_dirs": body.shapedirs.detach().cpu().numpy().reshape(len(vertices), -1),
    }
    if body.has_pose_blendshapes:
        surface["pose_dirs"] = body.posedirs.detach().cpu().numpy().reshape(len(vertices), -1)

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
    sdf_lower, sdf_mask, _, sdf_values = _surface_band(
        query, sdf_coarse, config.sdf_spacing, config.sdf_band, config.sdf_band
    )
    sdf_fine = SparseGrid(
        torch.from_numpy(sdf_lower),
        config.sdf_spacing,
        torch.from_numpy(sdf_mask),
        {"sdf": torch.from_numpy(sdf_values)[:, None]},
    )
    report("signed distance", 2, 2)
    timings["sdf_s"] = time.perf_counter() - t0

    # Sparse field levels: (origin, spacing, mask, masked nodes, groups), finest first.
    everything = tuple(surface)
    layout: list[tuple[np.ndarray, float, np.ndarray, np.ndarray, tuple[str, ...]]] = []
    for level in config.levels:
        groups = tuple(g for g in level.groups if g in surface)
        if groups:
            origin, mask, nodes, _ = _surface_band(
                query, sdf_coarse, level.spacing, level.outside, level.inside
            )
            layout.append((origin, level.spacing, mask, nodes, groups))

    # Field values at the nodes.
    t0 = time.perf_counter()
    mlps: dict[str, FieldMLP] = {}
    losses: dict[str, float] = {}
    if config.method == "mlp":
        mlps, losses = _fit_mlps(query, surface, config, rng, report)
        timings["mlp_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()

    def node_values(
        nodes: np.ndarray, groups: tuple[str, ...], spacing: float
    ) -> dict[str, torch.Tensor]:
        """Group → ``(M, C)`` values at ``nodes`` ``(M, 3)``, the weights floored."""
        if config.method == "mlp":
            values = {g: mlps[g].evaluate(torch.from_numpy(nodes)) for g in groups}
        else:
            stacked = np.concatenate([surface[g] for g in groups], axis=1)
            done = [0]

            def _progress(n: int) -> None:
                done[0] += n
                report(f"diffusion, {spacing * 1000:g} mm grid", done[0], len(nodes))

            diffused = query.diffuse(nodes, stacked, config.diffusion_samples, rng, _progress)
            parts = np.split(diffused, np.cumsum([surface[g].shape[1] for g in groups])[:-1], 1)
            values = {g: torch.from_numpy(v.copy()) for g, v in zip(groups, parts, strict=True)}
        if "weights" in values:
            values["weights"] = _floor_weights(values["weights"], config.weight_floor)
        return values

    levels = [
        SparseGrid(
            torch.from_numpy(origin),
            spacing,
            torch.from_numpy(mask),
            node_values(nodes, groups, spacing),
        )
        for origin, spacing, mask, nodes, groups in layout
    ]
    box_nodes, box_shape = _lattice(lower, upper, config.coarse_field_spacing)
    box_values = node_values(box_nodes, everything, config.coarse_field_spacing)
    fields_coarse = DenseGrid(
        torch.from_numpy(lower),
        config.coarse_field_spacing,
        {k: v.reshape(*box_shape, -1) for k, v in box_values.items()},
    )
    timings["field_values_s"] = time.perf_counter() - t0

    settings = asdict(config)
    if config.method == "direct":
        settings = {k: v for k, v in settings.items() if k not in MLP_SETTINGS}
    meta = {
        **settings,
        "diffusion_std": "d (the distance to the surface)",
        "body": body.name,
        "num_betas": NUM_BETAS,
        **({"final_losses": losses} if losses else {}),
        "timings_s": {k: round(v, 1) for k, v in timings.items()},
    }
    state = _mlp_state(mlps) if mlps else None
    return BodyFields(levels, fields_coarse, sdf_fine, sdf_coarse, body.name, meta, state)


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
