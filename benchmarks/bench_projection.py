"""Benchmark of the projection of simulated garments to canonical space (the paper's Sec. 3.3),
against the two unposing baselines of its Fig. 5, measured in the same run.

Simulates a few short T-shirt sequences (procedural motions × random body shapes, Newton
Style3D; cached under scratch/projection/ as .npz, so later runs only project), then for each
method prints: mean and p99 reprojection error (m_sim vs the method's own forward model, mm),
share of canonical vertices inside the canonical body and within 1 mm of it (exact signed
distance to the β = 0 T-pose body mesh), mean per-vertex acceleration of X in canonical space
(m/s², 30 fps), and throughput (frames/s on this CPU).

    python benchmarks/bench_projection.py [--lod high] [--frames 60] [--iterations 40]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.canonical.projection import ProjectionSettings, project_sequence
from usd_garment.canonical.unpose import (
    skin_body_vertices,
    unpose_constant_weights,
    unpose_nearest_vertex,
)
from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.garment.model import GarmentModel
from usd_garment.motion.procedural import make_motion, random_betas
from usd_garment.motion.sequence import SmplMotion
from usd_garment.sim.cloth import simulate_sequence

FPS = 30.0
CACHE = Path(__file__).resolve().parents[1] / "scratch" / "projection"
#: (motion kind, motion seed, shape seed; None: the mean shape).
SEQUENCES = (("arm_raise", 1, None), ("torso_twist", 2, 11), ("walk", 3, 12), ("arm_swing", 4, 13))
LEAD_IN = 10


def simulate(
    body: BodyModel, lod: str, kind: str, seed: int, shape_seed: int | None, frames: int
) -> tuple[SmplMotion | None, np.ndarray | None]:
    """``(motion, points (T, N, 3))`` of one cached or newly simulated sequence; ``(None,
    None)`` when its simulation failed (remembered in a ``.failed`` file beside the cache)."""
    path = CACHE / f"sim_tshirt_{lod}_{kind}_{seed}_{shape_seed}_{frames}.npz"
    failed = path.with_suffix(".failed")
    if failed.is_file():
        print(f"{kind} (shape seed {shape_seed}): simulation failed before, skipped "
              f"({failed.read_text().strip()})")  # fmt: skip
        return None, None
    if path.is_file():
        with np.load(path) as data:
            motion = SmplMotion(data["betas"], data["pose"], data["trans"], fps=FPS)
            return motion, data["points"]
    betas = np.zeros(10, np.float32)
    if shape_seed is not None:
        betas = random_betas(np.random.default_rng(shape_seed), sigma=1.0)
    motion = make_motion(kind, frames, FPS, seed=seed, betas=betas, body=body)
    template = load_template("tshirt", lod)
    with torch.no_grad():
        b = torch.as_tensor(motion.betas).float()
        posed = body(b, torch.as_tensor(motion.pose).float(), torch.as_tensor(motion.trans).float())
        # Lead-in: the rest body grows into the motion's shape and first pose.
        s = torch.arange(1, LEAD_IN + 1, dtype=torch.float32) / LEAD_IN
        s = s * s * (3 - 2 * s)
        lead = body(
            s[:, None] * b, s[:, None, None] * torch.as_tensor(motion.pose[:1]).float(),
            s[:, None] * torch.as_tensor(motion.trans[:1]).float(),
        )  # fmt: skip
        rest = body(torch.zeros(10), torch.zeros(1, 24, 3)).vertices[0]
    result = simulate_sequence(
        template.vertices, template.faces, body.faces.numpy(), posed.vertices.double().numpy(),
        body_rest=rest.double().numpy(), lead_in=lead.vertices.double().numpy(), fps=FPS,
    )  # fmt: skip
    CACHE.mkdir(parents=True, exist_ok=True)
    if not result.ok:
        failed.write_text(result.message + "\n")
        print(f"{kind} (shape seed {shape_seed}): simulation failed, skipped ({result.message})")
        return None, None
    np.savez_compressed(
        path, betas=motion.betas, pose=motion.pose, trans=motion.trans, points=result.points
    )
    return motion, result.points


def measures(
    canonical: np.ndarray, error: np.ndarray, body: BodyModel, surface: BodySurface
) -> dict[str, float]:
    """Collision shares in the canonical body, acceleration and error figures of one method."""
    rest = np.repeat(body.v_template.numpy()[None], len(canonical), axis=0)
    sdf = signed_distance(canonical, rest, surface).distance
    acc = np.linalg.norm(canonical[2:] - 2 * canonical[1:-1] + canonical[:-2], axis=-1) * FPS**2
    return {
        "inside": float((sdf < 0).mean()),
        "within_1mm": float((sdf < 1e-3).mean()),
        "acc": float(acc.mean()),
        "err_mean": float(error.mean()),
        "err_p99": float(np.percentile(error, 99)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lod", default="high")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--iterations", type=int, default=ProjectionSettings.iterations)
    parser.add_argument("--chunk", type=int, default=ProjectionSettings.chunk)
    parser.add_argument("--sequences", type=int, default=len(SEQUENCES))
    parser.add_argument("--fields", default=None, help="body fields file (default: embedded)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    body = load_body_model()
    template = load_template("tshirt", args.lod)
    draped = load_template("tshirt", args.lod, draped=True)
    model = GarmentModel(body, load_body_fields(args.fields))
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    settings = ProjectionSettings(iterations=args.iterations, chunk=args.chunk)
    print(f"T-shirt {args.lod}: {len(template.vertices)} vertices; {settings}")
    totals: dict[str, list[dict[str, float]]] = {}
    seconds: dict[str, float] = {}
    frames_total = 0
    for kind, seed, shape_seed in SEQUENCES[: args.sequences]:
        started = time.perf_counter()
        motion, points = simulate(body, args.lod, kind, seed, shape_seed, args.frames)
        if motion is None or points is None:
            continue
        print(f"{kind} (shape seed {shape_seed}): {len(points)} frames, "
              f"ready in {time.perf_counter() - started:.1f} s")  # fmt: skip
        frames_total += len(points)
        args_m = (motion.betas, motion.pose, motion.trans)
        runs = {}
        t0 = time.perf_counter()
        ours = project_sequence(model, template.vertices, template.faces, points, *args_m,
                                settings, start=draped.vertices)  # fmt: skip
        runs["ours"] = (ours.canonical, np.linalg.norm(
            model(torch.as_tensor(ours.canonical), *(torch.as_tensor(a) for a in args_m)
                  ).vertices.detach().numpy() - points, axis=-1))  # fmt: skip
        t1 = time.perf_counter()
        const = unpose_constant_weights(body, template, points, *args_m)
        t2 = time.perf_counter()
        near = unpose_nearest_vertex(body, points, *args_m)
        t3 = time.perf_counter()
        for name, result in (("constant weights", const), ("per-frame nearest vertex", near)):
            again = skin_body_vertices(body, result.canonical, result.body_vertex, *args_m)
            runs[name] = (result.canonical, np.linalg.norm(again - points, axis=-1))
        for name, dt in (("ours", t1 - t0), ("constant weights", t2 - t1),
                         ("per-frame nearest vertex", t3 - t2)):  # fmt: skip
            seconds[name] = seconds.get(name, 0.0) + dt
        for name, (canonical, error) in runs.items():
            m = measures(canonical, error, body, surface)
            totals.setdefault(name, []).append(m)
            print(f"  {name:26s} err mean {1e3 * m['err_mean']:6.3f} mm p99 "
                  f"{1e3 * m['err_p99']:6.3f} mm | inside {100 * m['inside']:7.3f}% "
                  f"<1 mm {100 * m['within_1mm']:7.3f}% | acc {m['acc']:6.3f} m/s²")  # fmt: skip
    print(f"all {frames_total} frames:")
    for name, ms in totals.items():
        mean = {k: float(np.mean([m[k] for m in ms])) for k in ms[0]}
        rate = frames_total / seconds[name]
        print(f"  {name:26s} err mean {1e3 * mean['err_mean']:6.3f} mm | inside "
              f"{100 * mean['inside']:7.3f}% <1 mm {100 * mean['within_1mm']:7.3f}% | "
              f"acc {mean['acc']:6.3f} m/s² | {rate:8.2f} frames/s")  # fmt: skip


if __name__ == "__main__":
    main()
