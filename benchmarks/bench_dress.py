"""Benchmark of the stage processor: ``dress --method lbs`` on a 1,000-frame procedural animation,
in-process and once through the CLI, with the share of time in read, compute and write; and the
``lbs+postprocess`` baseline on a slice of the same animation for comparison.

Run: ``python benchmarks/bench_dress.py [--frames 1000] [--postprocess-frames 100]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from usd_garment.body import load_body_model
from usd_garment.dress import dress
from usd_garment.motion.amass import load_amass
from usd_garment.usd.body_layer import write_body_layer


def procedural_npz(path: Path, frames: int, fps: float = 30.0) -> None:
    """An AMASS-style npz (Z-up, SMPL-H layout): a swaying, arm-swinging walk forward."""
    t = np.arange(frames) / fps
    rng = np.random.default_rng(0)
    poses = np.zeros((frames, 156))
    poses[:, :3] = [np.pi / 2, 0.0, 0.0]
    amp = 0.15 + 0.25 * rng.random(63)
    freq = 0.5 + 1.5 * rng.random(63)
    poses[:, 3:66] = amp * np.sin(2 * np.pi * freq * t[:, None] + rng.random(63) * 6.28)
    trans = np.stack([0.3 * np.sin(0.5 * t), 1.2 * t, 0.9 + 0.02 * np.sin(4 * t)], axis=1)
    np.savez(path, poses=poses, trans=trans, betas=np.zeros(16), gender="neutral",
             mocap_framerate=fps)  # fmt: skip


def report(label: str, summary: dict) -> float:
    s = summary["seconds"]
    total = sum(s.values())
    shares = ", ".join(f"{k} {v:.2f} s ({100 * v / total:.0f}%)" for k, v in s.items())
    fps = summary["frames"] / total
    print(f"{label}: {summary['frames']} frames x {summary['vertices']} vertices, "
          f"{fps:.1f} frames/s; {shares}")  # fmt: skip
    return fps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--postprocess-frames", type=int, default=100)
    args = parser.parse_args()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        npz, body_usd = folder / "walk.npz", folder / "walk.usdc"
        start = time.perf_counter()
        procedural_npz(npz, args.frames)
        body = load_body_model()
        write_body_layer(body_usd, load_amass(npz, body), body)
        print(f"built {args.frames}-frame body layer in {time.perf_counter() - start:.1f} s")

        lbs = dress(body_usd, folder / "lbs.usdc", method="lbs").to_json()
        lbs_fps = report("lbs (in-process)", lbs)

        start = time.perf_counter()
        cli = subprocess.run(
            [str(Path(sys.executable).with_name("usd-garment")), "dress", str(body_usd),
             "-o", str(folder / "cli.usdc"), "--method", "lbs", "--json"],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        wall = time.perf_counter() - start
        cli_summary = json.loads(cli.stdout)
        report("lbs (CLI)", cli_summary)
        print(f"lbs (CLI) wall time incl. interpreter start: {wall:.2f} s, "
              f"{args.frames / wall:.1f} frames/s")  # fmt: skip

        n = min(args.postprocess_frames, args.frames)
        pp = dress(body_usd, folder / "pp.usdc", method="lbs+postprocess", frames=(0, n)).to_json()
        pp_fps = report(f"lbs+postprocess (in-process, first {n} frames)", pp)
        compute_ratio = (pp["seconds"]["compute"] / pp["frames"]) / (
            lbs["seconds"]["compute"] / lbs["frames"]
        )
        print(f"baseline ratio: lbs is {lbs_fps / pp_fps:.1f}x faster end to end than "
              f"lbs+postprocess; compute per frame {compute_ratio:.1f}x")  # fmt: skip


if __name__ == "__main__":
    main()
