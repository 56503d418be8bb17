"""Benchmark and acceptance figures of the diffused body fields: grid speed at 4,400 points × 30
frames, surface skinning-weight error, smoothness across medial axes, the grid against the
diffusion computed directly at random points, and the SDF grid's error against the exact signed
distance. With ``--mlp FILE`` (fields made with ``fields fit --method mlp``), the same figures of
that file's grid and of its MLPs are printed beside them.

Run: ``python benchmarks/bench_fields.py [FIELDS.npz] [--mlp FILE] [--body-model PATH] [--json]``
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import torch

from usd_garment.body import BodyModel, load_body_model
from usd_garment.fields import BodyFields, load_body_fields
from usd_garment.fields.evaluate import (
    evaluate_fields,
    medial_axis_smoothness,
    near_surface_points,
    surface_weight_error,
)
from usd_garment.fields.fit import mlps_from_state

GARMENT_VERTICES = 4_400
FRAMES = 30


def _best_time(fn: Callable[[], object], repeats: int = 3) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def speed(fields: BodyFields, body: BodyModel) -> dict[str, float]:
    """Points per second of the grid (weights + shape blendshapes, and SDF) and of the MLPs."""
    pts = near_surface_points(body, GARMENT_VERTICES, seed=3)
    pts = torch.from_numpy(pts)[None].repeat(FRAMES, 1, 1)
    pts = pts + 0.005 * torch.randn(pts.shape, generator=torch.Generator().manual_seed(0))
    n = pts.shape[0] * pts.shape[1]
    with torch.no_grad():
        grid_s = _best_time(lambda: fields.all_fields(pts))
        sdf_s = _best_time(lambda: fields.sdf(pts))
        out = {"points": n, "grid_points_per_s": n / grid_s, "sdf_points_per_s": n / sdf_s}
        if fields.mlp_state is not None:
            mlps = mlps_from_state(fields.mlp_state)
            flat = pts.reshape(-1, 3)
            mlp_s = _best_time(lambda: [m.evaluate(flat) for m in mlps.values()], repeats=1)
            out |= {"mlp_points_per_s": n / mlp_s, "grid_speedup": mlp_s / grid_s}
    pts.requires_grad_(True)
    grad_s = _best_time(lambda: fields.all_fields(pts)[0].sum().backward())
    out["grid_with_backward_points_per_s"] = n / grad_s
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fields", nargs="?", default=None, help="fields file (default: shipped)")
    parser.add_argument("--mlp", default=None, help="fields file with MLPs to compare against")
    parser.add_argument("--body-model", default=None, help="body the fields were fitted to")
    parser.add_argument("--json", action="store_true", help="print JSON only")
    args = parser.parse_args()
    fields = load_body_fields(args.fields)
    body = load_body_model(args.body_model)
    result = {"speed": speed(fields, body), **evaluate_fields(fields, body)}
    if args.mlp is not None:
        other = load_body_fields(args.mlp)
        if other.mlp_state is None:
            parser.error(f"{args.mlp}: holds no MLPs")
        result["mlp_file"] = {
            "path": args.mlp,
            "config": other.config,
            "speed": speed(other, body),
            "surface_weights": surface_weight_error(other, body),
            "medial_axis": medial_axis_smoothness(other, body),
        }
    if args.json:
        print(json.dumps(result, indent=2))
        return
    s = result["speed"]
    print(
        f"speed, {s['points']} points ({GARMENT_VERTICES} x {FRAMES} frames), CPU, "
        f"{torch.get_num_threads()} threads"
    )
    print(f"  grid (weights + shape dirs)   {s['grid_points_per_s']:,.0f} points/s")
    mlp_file = result.get("mlp_file")
    mlp_speed = mlp_file["speed"] if mlp_file else s
    if "mlp_points_per_s" in mlp_speed:
        print(f"  MLPs (weights + shape dirs)   {mlp_speed['mlp_points_per_s']:,.0f} points/s")
        ratio = s["grid_points_per_s"] / mlp_speed["mlp_points_per_s"]
        print(f"  grid / MLP speed ratio        {ratio:.1f}x")
    print(f"  grid forward + backward       {s['grid_with_backward_points_per_s']:,.0f} points/s")
    print(f"  SDF grid                      {s['sdf_points_per_s']:,.0f} points/s")
    method = fields.config.get("method", "mlp")
    print("skinning weights at the body vertices vs the body's own (L1 over joints)")
    rows = [(f"{method} grid", result["surface_weights"], "grid")]
    if "mlp_mean_l1" in result["surface_weights"]:
        rows.append(("its MLP", result["surface_weights"], "mlp"))
    if mlp_file:
        rows += [("--mlp grid", mlp_file["surface_weights"], "grid")]
        rows += [("--mlp MLP", mlp_file["surface_weights"], "mlp")]
    for label, sw, key in rows:
        print(f"  {label:<12} mean {sw[f'{key}_mean_l1']:.4f}  p99 {sw[f'{key}_p99_l1']:.4f}")
    print("largest weight change along medial-axis segments (L1 per m, 1 mm steps)")
    for name, m in result["medial_axis"].items():
        extra = ""
        if mlp_file:
            extra = f"   --mlp grid {mlp_file['medial_axis'][name]['diffused_max_per_m']:8.1f}"
        print(
            f"  {name:<15} {method} grid {m['diffused_max_per_m']:8.1f}   "
            f"nearest vertex {m['nearest_vertex_max_per_m']:8.1f}{extra}"
        )
    g = result["grid_vs_diffusion"]
    print(
        f"grid vs the diffusion computed at {g['points']} random points within 3 cm of the "
        f"surface (N = {g['samples']})"
    )
    print(f"  weights L1 mean {g['weights_mean_l1']:.4f}  p99 {g['weights_p99_l1']:.4f}")
    print(
        f"  shape dirs mean {g['shape_dirs_mean_abs_m'] * 1000:.4f} mm/beta  "
        f"p99 {g['shape_dirs_p99_abs_m'] * 1000:.4f} mm/beta"
    )
    print(
        f"  (the reference's own Monte Carlo noise: weights L1 mean "
        f"{g['reference_noise_weights_mean_l1']:.4f}  p99 "
        f"{g['reference_noise_weights_p99_l1']:.4f})"
    )
    d = result["sdf"]
    print(f"SDF grid vs exact, {d['points']} points within 3 cm of the surface")
    print(
        f"  mean {d['mean_abs_m'] * 1000:.3f} mm  p99 {d['p99_abs_m'] * 1000:.3f} mm  "
        f"max {d['max_abs_m'] * 1000:.3f} mm"
    )
    print(
        f"  sign errors within 2 mm: {d['sign_error_share_within_2mm'] * 100:.3f}% "
        f"of {d['points_within_2mm']} points"
    )
    if "grid_vs_mlp" in result:
        g = result["grid_vs_mlp"]
        print(f"grid vs MLP, {g['points']} points drawn like the training points")
        print(f"  weights L1 mean {g['weights_mean_l1']:.4f}  p99 {g['weights_p99_l1']:.4f}")
        print(
            f"  shape dirs mean {g['shape_dirs_mean_abs_m'] * 1000:.4f} mm/beta  "
            f"p99 {g['shape_dirs_p99_abs_m'] * 1000:.4f} mm/beta"
        )


if __name__ == "__main__":
    main()
