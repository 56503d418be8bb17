"""Acceptance figures of the diffused body fields and the SDF grid: surface skinning-weight error,
smoothness across medial axes, SDF error against the exact signed distance, and the baked grid
against the diffusion computed directly at random points (and against the fitted MLPs, when the
grid was baked from them). Units: metres; weight errors are L1 over the 24 joints.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from usd_garment.body.joints import SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel
from usd_garment.fields.body_fields import BodyFields
from usd_garment.fields.diffusion import BodySurfaceQuery
from usd_garment.fields.fit import FitConfig, mlps_from_state, sample_training_points

#: Sampling step along the medial-axis segments (m).
SEGMENT_STEP = 0.001


def surface_weight_error(fields: BodyFields, body: BodyModel) -> dict[str, float]:
    """L1 distance between the field's weights at the rest body vertices and the body's own
    weights: mean and 99th percentile over vertices, for the grid (and the MLP when stored)."""
    v = body.v_template
    with torch.no_grad():
        err = (fields.weights(v) - body.weights).abs().sum(-1).numpy()
    out = {"grid_mean_l1": float(err.mean()), "grid_p99_l1": float(np.percentile(err, 99))}
    if fields.mlp_state is not None:
        mlp = mlps_from_state(fields.mlp_state)["weights"]
        e = (mlp.evaluate(v) - body.weights).abs().sum(-1).numpy()
        out |= {"mlp_mean_l1": float(e.mean()), "mlp_p99_l1": float(np.percentile(e, 99))}
    return out


def medial_axis_segments(body: BodyModel) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Segments (start, end) crossing medial-axis regions of the rest body, from its joints:
    between the thighs (left to right, 40% of the way from hips to knees) and under each armpit
    (downward from the upper arm, a third of the way from shoulder to elbow)."""
    with torch.no_grad():
        j = body.shaped(torch.zeros(1, 10))[1][0].numpy()
    idx = {n: i for i, n in enumerate(SMPL_JOINT_NAMES)}
    hips = (j[idx["left_hip"]] + j[idx["right_hip"]]) / 2
    knees = (j[idx["left_knee"]] + j[idx["right_knee"]]) / 2
    thigh = hips + 0.4 * (knees - hips)
    half = abs(j[idx["left_hip"], 0] - j[idx["right_hip"], 0])
    across = np.array([half * 1.5, 0.0, 0.0])
    segments = {"between_legs": (thigh - across, thigh + across)}
    for side in ("left", "right"):
        sh, el = j[idx[f"{side}_shoulder"]], j[idx[f"{side}_elbow"]]
        top = sh + (el - sh) / 3
        segments[f"under_{side}_arm"] = (top, top - np.array([0.0, 0.3, 0.0]))
    return {
        k: (np.asarray(a, np.float32), np.asarray(b, np.float32)) for k, (a, b) in segments.items()
    }


def _max_rate(values: np.ndarray, step: float) -> float:
    """Largest L1 change per metre between consecutive rows of ``values`` ``(n, C)``."""
    return float(np.abs(np.diff(values, axis=0)).sum(-1).max() / step)


def medial_axis_smoothness(fields: BodyFields, body: BodyModel) -> dict[str, dict[str, float]]:
    """Largest spatial rate of change of the skinning weights (L1 per metre, finite differences at
    1 mm) along each medial-axis segment: the diffused field versus the nearest-vertex
    assignment (which jumps where the nearest vertex switches sides)."""
    tree = cKDTree(body.v_template.numpy())
    out = {}
    for name, (a, b) in medial_axis_segments(body).items():
        n = int(np.linalg.norm(b - a) / SEGMENT_STEP) + 1
        pts = a + np.linspace(0, 1, n)[:, None] * (b - a)
        with torch.no_grad():
            w = fields.weights(torch.from_numpy(pts.astype(np.float32))).numpy()
        nearest = body.weights.numpy()[tree.query(pts)[1]]
        step = np.linalg.norm(b - a) / (n - 1)
        out[name] = {
            "diffused_max_per_m": _max_rate(w, step),
            "nearest_vertex_max_per_m": _max_rate(nearest, step),
        }
    return out


def near_surface_points(body: BodyModel, count: int, seed: int) -> np.ndarray:
    """``(count, 3)`` points near the rest surface: random surface points offset along the face
    normal by N(0, (1 cm)²), clipped to ±3 cm."""
    rng = np.random.default_rng(seed)
    v, f = body.v_template.numpy(), body.faces.numpy()
    config = FitConfig(samples=count, surface_share=1.0, near_share=0.0)
    on = sample_training_points(v, f, config, rng)
    tri = v[f]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # Offset along the normal of the nearest face centroid (cheap and good enough for sampling).
    face = cKDTree(tri.mean(1)).query(on)[1]
    n = normals[face] / np.linalg.norm(normals[face], axis=1, keepdims=True)
    offset = np.clip(rng.normal(scale=0.01, size=count), -0.03, 0.03)
    return (on + offset[:, None] * n).astype(np.float32)


def sdf_error(fields: BodyFields, body: BodyModel, count: int = 100_000, seed: int = 1) -> dict:
    """Baked SDF against the exact signed distance at points near the surface: mean / max
    absolute error (m), and the share of sign errors among points within 2 mm of the surface."""
    pts = near_surface_points(body, count, seed)
    exact = BodySurfaceQuery(body.v_template.numpy(), body.faces.numpy()).signed_distance(pts)
    with torch.no_grad():
        grid = fields.sdf(torch.from_numpy(pts)).numpy()
    err = np.abs(grid - exact)
    close = np.abs(exact) < 0.002
    wrong = np.sign(grid[close]) != np.sign(exact[close])
    return {
        "points": count,
        "mean_abs_m": float(err.mean()),
        "p99_abs_m": float(np.percentile(err, 99)),
        "max_abs_m": float(err.max()),
        "points_within_2mm": int(close.sum()),
        "sign_error_share_within_2mm": float(wrong.mean()) if close.any() else 0.0,
    }


def grid_vs_diffusion(
    fields: BodyFields,
    body: BodyModel,
    count: int = 20_000,
    seed: int = 4,
    samples: int = 256,
) -> dict[str, float]:
    """Baked grids against the paper's diffusion computed directly (``samples`` Gaussian samples)
    at ``count`` random points within 3 cm of the surface: weights L1 (mean, p99) and
    shape-blendshape absolute difference (m per unit β). The reference is itself a Monte Carlo
    estimate; its own noise (L1 between two independent estimates at the same points) is
    reported too."""
    pts = near_surface_points(body, count, seed)
    query = BodySurfaceQuery(body.v_template.numpy(), body.faces.numpy())
    values = np.concatenate(
        [body.weights.numpy(), body.shapedirs.numpy().reshape(body.num_vertices, -1)], axis=1
    )
    rng = np.random.default_rng(seed)
    ref, again = (query.diffuse(pts, values, samples, rng) for _ in range(2))
    with torch.no_grad():
        w, s, _ = fields.all_fields(torch.from_numpy(pts))
    dw = np.abs(w.numpy() - ref[:, :24]).sum(-1)
    ds = np.abs(s.flatten(1).numpy() - ref[:, 24:])
    noise = np.abs(again[:, :24] - ref[:, :24]).sum(-1)
    return {
        "points": count,
        "samples": samples,
        "weights_mean_l1": float(dw.mean()),
        "weights_p99_l1": float(np.percentile(dw, 99)),
        "shape_dirs_mean_abs_m": float(ds.mean()),
        "shape_dirs_p99_abs_m": float(np.percentile(ds, 99)),
        "reference_noise_weights_mean_l1": float(noise.mean()),
        "reference_noise_weights_p99_l1": float(np.percentile(noise, 99)),
    }


def grid_vs_mlp(fields: BodyFields, body: BodyModel, count: int = 50_000, seed: int = 2) -> dict:
    """Baked grids against the fitted MLPs at points drawn like the training points (a different
    seed): weights L1 (mean, p99) and shape-blendshape absolute difference (m per unit β)."""
    if fields.mlp_state is None:
        raise ValueError("these fields hold no MLP state to compare against")
    mlps = mlps_from_state(fields.mlp_state)
    v, f = body.v_template.numpy(), body.faces.numpy()
    pts = torch.from_numpy(
        sample_training_points(v, f, FitConfig(samples=count), np.random.default_rng(seed))
    )
    with torch.no_grad():
        w, s, _ = fields.all_fields(pts)
    dw = (w - mlps["weights"].evaluate(pts)).abs().sum(-1).numpy()
    ds = (s.flatten(1) - mlps["shape_dirs"].evaluate(pts)).abs().numpy()
    return {
        "points": count,
        "weights_mean_l1": float(dw.mean()),
        "weights_p99_l1": float(np.percentile(dw, 99)),
        "shape_dirs_mean_abs_m": float(ds.mean()),
        "shape_dirs_p99_abs_m": float(np.percentile(ds, 99)),
    }


def evaluate_fields(fields: BodyFields, body: BodyModel) -> dict[str, Any]:
    """All acceptance figures in one dictionary."""
    out: dict[str, Any] = {
        "surface_weights": surface_weight_error(fields, body),
        "medial_axis": medial_axis_smoothness(fields, body),
        "sdf": sdf_error(fields, body),
        "grid_vs_diffusion": grid_vs_diffusion(fields, body),
    }
    if fields.mlp_state is not None:
        out["grid_vs_mlp"] = grid_vs_mlp(fields, body)
    return out
