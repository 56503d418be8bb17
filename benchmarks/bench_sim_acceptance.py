"""Acceptance figures of the training-data simulator: a T-shirt dataset of 5 procedural motions ×
3 body shapes, 90 frames each, made with ``make_dataset`` and then measured from the written USD
layers with the shared body distance query (``usd_garment.eval.body_distance``: winding-number
inside test, inside split into *forced*, where a body part is pressed into another, and
*elsewhere*, the simulation's fault), recomputed from the layers rather than read from the
simulator's own checks.

Criteria: no NaN; inside-elsewhere ≤ 0.05 % of vertices on average and ≤ 0.5 % in every frame
(inside in all, forced included, printed beside it); no frame with a vertex farther than 10 cm
from the body surface; edge stretch p99 ≤ 1.15 (current / rest length, rest
= the template graded to the sequence's body shape, as simulated), printed both pooled over all
edges of all frames and as the worst frame's own p99 (the stricter reading); and seconds per
frame.
For reference beside the garment's stretch, the body's own skin stretch under skinning (posed /
shaped rest edge lengths of the body mesh, p99 per frame): a garment in contact follows it.

    python benchmarks/bench_sim_acceptance.py [-o scratch/sim_acceptance] [--workers 2]
    python benchmarks/bench_sim_acceptance.py --evaluate DIR [--motions 5]

``-o`` resumes a dataset already made there with the same settings. ``--evaluate`` measures the
first ``--motions`` motions × ``--shapes`` shapes of an existing dataset instead: the plan of a
seeded dataset starts with that of fewer motions and shapes, so the first 5 motions × 3 shapes
of ``dataset make --seed 0`` are the sequences this script would simulate with ``--seed 0``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.eval.evaluate import posed_body_vertices
from usd_garment.garment.library import load_template
from usd_garment.methods.simulation import shape_offsets
from usd_garment.sim.checks import edge_lengths, unique_edges
from usd_garment.training.dataset import DatasetConfig, make_dataset, read_manifest
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion

MAX_ELSEWHERE_MEAN = 0.0005
MAX_ELSEWHERE_FRAME = 0.005
MAX_DISTANCE = 0.10
MAX_STRETCH_P99 = 1.15


def measure(folder: Path, motions: int | None = None, shapes: int | None = None) -> None:
    """Print per-sequence and overall figures of the dataset in ``folder`` (its first
    ``motions`` motions and ``shapes`` shapes; all by default), and the verdicts."""
    manifest = read_manifest(folder)
    body = load_body_model(None)
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    template = load_template(manifest["garment"], manifest["lod"])
    edges = unique_edges(template.faces)
    body_edges = unique_edges(body.faces.numpy())
    rows = []
    for entry in manifest["sequences"]:
        if motions is not None and entry["motion_index"] >= motions:
            continue
        if shapes is not None and entry["shape_index"] >= shapes:
            continue
        if entry["status"] == "pending":
            print(f"{entry['name']:8s} {entry['motion_kind']:14s} not simulated yet")
            continue
        if entry["status"] != "ok":
            print(f"{entry['name']:8s} {entry['motion_kind']:14s} {entry['status']}: "
                  f"{entry.get('message', '')}")  # fmt: skip
            rows.append(None)
            continue
        points = read_garment_layer(folder / entry["files"]["garment"])[0]
        motion, _ = read_smpl_motion(folder / entry["files"]["body"], body)
        posed = posed_body_vertices(body, motion)
        query = signed_distance(points, posed, surface)
        sdf = query.distance
        rest = template.vertices + shape_offsets(body, template.vertices, motion.betas)
        ratio = (edge_lengths(points, edges) / edge_lengths(rest, edges)).astype(np.float32)
        stretch = np.percentile(ratio, 99, axis=1)
        with torch.no_grad():
            body_rest = body.shaped(torch.as_tensor(motion.betas)[None])[0][0].numpy()
        skin_ratio = edge_lengths(posed, body_edges) / edge_lengths(body_rest, body_edges)
        skin = np.percentile(skin_ratio, 99, axis=1)
        row = {
            "nan": int((~np.isfinite(points)).any(axis=-1).sum()),
            "inside": query.inside.mean(axis=1),
            "forced": query.forced.mean(axis=1),
            "elsewhere": query.elsewhere.mean(axis=1),
            "distance": np.abs(sdf).max(axis=1),
            "stretch": stretch,
            "ratio": ratio,
            "skin": skin,
            "s_per_frame": entry["checks"]["seconds_per_frame"],
            "retried": len(entry["checks"]["retries"]),
        }
        rows.append(row)
        print(
            f"{entry['name']:8s} {entry['motion_kind']:14s} |β| {np.linalg.norm(motion.betas):4.2f}"
            f"  NaN {row['nan']}  inside forced mean {100 * row['forced'].mean():.3f}% max "
            f"{100 * row['forced'].max():.3f}%, elsewhere mean {100 * row['elsewhere'].mean():.3f}%"
            f" max {100 * row['elsewhere'].max():.3f}%  max dist {row['distance'].max():.3f} m  "
            f"stretch p99 max {stretch.max():.3f} (skin {skin.max():.3f})  "
            f"{row['s_per_frame']:.2f} s/frame  "
            f"retried frames {row['retried']}"
        )
    good = [r for r in rows if r is not None]
    if not good:
        print("no sequence simulated")
        return
    inside_mean = float(np.mean(np.concatenate([r["inside"] for r in good])))
    forced_mean = float(np.mean(np.concatenate([r["forced"] for r in good])))
    elsewhere = np.concatenate([r["elsewhere"] for r in good])
    elsewhere_mean, elsewhere_max = float(elsewhere.mean()), float(elsewhere.max())
    elsewhere_over = int((elsewhere > MAX_ELSEWHERE_FRAME).sum())
    elsewhere_ok = elsewhere_mean <= MAX_ELSEWHERE_MEAN and elsewhere_over == 0
    distance = max(float(r["distance"].max()) for r in good)
    far_frames = sum(int((r["distance"] > MAX_DISTANCE).sum()) for r in good)
    stretch_max = max(float(r["stretch"].max()) for r in good)
    stretch_over = sum(int((r["stretch"] > MAX_STRETCH_P99).sum()) for r in good)
    ratios = np.concatenate([r["ratio"].ravel() for r in good])
    pooled = float(np.percentile(ratios, 99))
    skin_there = np.concatenate([r["skin"][r["stretch"] > MAX_STRETCH_P99] for r in good])
    skin_note = (
        f"; the body's own skin stretch p99 on those frames: median {np.median(skin_there):.3f}"
        if len(skin_there)
        else ""
    )
    frames = sum(len(r["inside"]) for r in good)
    nan = sum(r["nan"] for r in good)
    print(
        f"\n{len(good)} of {len(rows)} sequences ok, {frames} frames ({manifest['garment']} "
        f"{manifest['lod']}, {manifest['vertices']} vertices)\n"
        f"sequences that failed the simulator's checks: {len(rows) - len(good)} "
        f"[{'PASS' if len(good) == len(rows) else 'FAIL'}]\n"
        f"NaN vertices in the sequences written: {nan}  [{'PASS' if nan == 0 else 'FAIL'}]\n"
        f"inside the body elsewhere (not forced by the pose), mean over frames: "
        f"{100 * elsewhere_mean:.4f}%, worst frame {100 * elsewhere_max:.3f}%, frames over 0.5%: "
        f"{elsewhere_over} [{'PASS' if elsewhere_ok else 'FAIL'} ≤ 0.05% mean, ≤ 0.5% per frame]"
        f"\n(inside in all {100 * inside_mean:.4f}%, forced by the pose {100 * forced_mean:.4f}%)\n"
        f"largest distance from the body: {distance:.3f} m, frames over 10 cm: {far_frames} "
        f"[{'PASS' if far_frames == 0 else 'FAIL'}]\n"
        f"edge stretch p99 over all edges of all frames: {pooled:.3f}, edges over 1.15: "
        f"{100 * float((ratios > MAX_STRETCH_P99).mean()):.3f}% "
        f"[{'PASS' if pooled <= MAX_STRETCH_P99 else 'FAIL'} ≤ 1.15]\n"
        f"edge stretch p99 per frame, worst frame: {stretch_max:.3f}, frames over 1.15: "
        f"{stretch_over} of {frames} [{'PASS' if stretch_over == 0 else 'FAIL'}]{skin_note}\n"
        f"seconds per simulated frame (lead-in included): mean "
        f"{np.mean([r['s_per_frame'] for r in good]):.3f}, max "
        f"{max(r['s_per_frame'] for r in good):.3f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("scratch/sim_acceptance"))
    parser.add_argument("--evaluate", type=Path, default=None, help="measure this dataset only")
    parser.add_argument("--motions", type=int, default=5)
    parser.add_argument("--shapes", type=int, default=3)
    parser.add_argument("--frames", type=int, default=90)
    parser.add_argument("--lod", default="high")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.evaluate is not None:
        measure(args.evaluate, args.motions, args.shapes)
        return
    config = DatasetConfig(
        "tshirt", args.lod, args.motions, args.shapes, args.frames, seed=args.seed
    )
    started = time.perf_counter()
    make_dataset(args.output, config, workers=args.workers, resume=True)
    print(f"made {args.output} in {time.perf_counter() - started:.0f} s ({args.workers} workers)")
    measure(args.output, args.motions, args.shapes)


if __name__ == "__main__":
    main()
