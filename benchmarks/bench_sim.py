"""Benchmark of the training-data cloth simulator: a T-shirt on the default body through a short
procedural motion (arms raised and lowered, torso twist), one run per level of detail.

Prints seconds per frame and the per-frame checks (share of vertices inside the body, largest
distance from it, edge stretch p99). Run one benchmark at a time: Warp uses one core per run.

    python benchmarks/bench_sim.py [--frames 60] [--lods low high]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.sim.cloth import easing, simulate_sequence

FPS = 30.0
LEFT_SHOULDER, RIGHT_SHOULDER = 16, 17
SPINE = (3, 6, 9)


def motion_poses(frames: int) -> np.ndarray:
    """``(T, 24, 3)`` axis-angle poses: arms from 45° down up to 20° above the horizontal and
    back down, while the torso twists ±0.5 rad about Y (spread over the three spine joints)."""
    t = np.arange(frames) / FPS
    duration = frames / FPS
    arm_down = np.radians(45.0) - np.radians(65.0) * np.sin(np.pi * t / duration) ** 2
    twist = 0.5 * np.sin(2.0 * np.pi * t / duration)
    pose = np.zeros((frames, 24, 3))
    pose[:, LEFT_SHOULDER, 2] = -arm_down  # the left arm points along +X in the T-pose
    pose[:, RIGHT_SHOULDER, 2] = arm_down
    for joint in SPINE:
        pose[:, joint, 1] = twist / len(SPINE)
    return pose


def skin(body: BodyModel, pose: np.ndarray) -> np.ndarray:
    """``(T, V, 3)`` posed vertices at β = 0."""
    with torch.no_grad():
        out = body(torch.zeros(10), torch.as_tensor(pose, dtype=torch.float32))
    return out.vertices.double().numpy()


def load_tshirt(body: BodyModel, lod: str) -> GarmentTemplate:
    """The embedded T-shirt template, or one built from ``body`` when none is embedded yet."""
    try:
        from usd_garment.garment.library import load_template

        return load_template("tshirt", lod)
    except (ImportError, FileNotFoundError):
        from usd_garment.garment.templates import make_template

        return make_template(body, "tshirt", lod)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--lead-in", type=int, default=10)
    parser.add_argument("--substeps", type=int, default=4)
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--lods", nargs="+", default=["low", "high"])
    args = parser.parse_args()

    body = load_body_model()
    faces = body.faces.numpy()
    poses = motion_poses(args.frames)
    frames = skin(body, poses)
    # The lead-in interpolates the pose (not the vertices) from the T-pose to the first frame.
    lead_in = skin(body, easing(args.lead_in)[:, None, None] * poses[:1])
    rest_body = skin(body, np.zeros((1, 24, 3)))[0]
    print(f"body {body.name}: {len(rest_body)} vertices; {args.frames} frames at {FPS:g} fps")
    for lod in args.lods:
        started = time.perf_counter()
        garment = load_tshirt(body, lod)
        built = time.perf_counter() - started
        result = simulate_sequence(
            garment.vertices, garment.faces, faces, frames, body_rest=rest_body,
            lead_in=lead_in, substeps=args.substeps, iterations=args.iterations, fps=FPS,
        )  # fmt: skip
        checks = result.checks
        print(
            f"tshirt {lod}: {len(garment.vertices)} v / {len(garment.faces)} f "
            f"(template {built:.1f} s), status {result.status} {result.message}\n"
            f"  {result.seconds_per_frame:.3f} s/frame (incl. checks, {args.lead_in} lead-in "
            f"+ 5 settle frames), substeps used max {max(result.substeps)}\n"
            f"  inside body: mean {100 * np.mean([c.inside_share for c in checks]):.3f}% "
            f"(forced by the pose {100 * np.mean([c.inside_forced_share for c in checks]):.3f}%,"
            f" elsewhere {100 * np.mean([c.inside_elsewhere_share for c in checks]):.3f}%, max "
            f"{100 * max(c.inside_elsewhere_share for c in checks):.3f}%); elsewhere deeper than "
            f"2 mm: max {100 * max(c.penetrating_share for c in checks):.3f}%; bad frames "
            f"{result.bad_frames}\n"
            f"  max distance from body {max(c.max_distance for c in checks):.3f} m; "
            f"edge stretch p99 max {max(c.stretch_p99 for c in checks):.3f}, "
            f"max {max(c.stretch_max for c in checks):.3f}"
        )


if __name__ == "__main__":
    main()
