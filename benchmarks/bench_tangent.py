"""Benchmark of the learned method's posing with the body fields taken to first order (the
default: about the mean canonical garment of each chunk, or of each part of it where the garment
moves far within it, ``_tangents``) against a field lookup at every frame (the exact M_G):
per-vertex distance between the two posed garments and the time of each, on a body layer.

Run: ``python benchmarks/bench_tangent.py BODY.usdc [--model DIR] [--chunk 256]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from usd_garment.body import load_body_model
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.model import GarmentModel
from usd_garment.methods.learned import LearnedMethod, Tangent, _tangents, predict_latents
from usd_garment.usd.read import read_smpl_motion


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("body")
    parser.add_argument("--model", default=None, help="model directory (default: shipped)")
    parser.add_argument("--chunk", type=int, default=256)
    args = parser.parse_args()
    body = load_body_model()
    motion, _ = read_smpl_motion(args.body, body)
    model = LearnedMethod(args.model).load("tshirt", body)
    fields = load_body_fields()
    garment_model = GarmentModel(body, fields)
    betas = torch.as_tensor(motion.betas)
    pose, trans = torch.as_tensor(motion.pose), torch.as_tensor(motion.trans)
    gaps, seconds = [], {"exact": 0.0, "linearized": 0.0}
    last: Tangent | None = None
    made = 0  # linearizations (a chunk may keep the last one)
    with torch.no_grad():
        z = predict_latents(model, motion)
        for s in range(0, motion.num_frames, args.chunk):
            e = min(s + args.chunk, motion.num_frames)
            x = model.decode(z[s:e])
            art = garment_model.articulation(betas, pose[s:e], trans[s:e])
            start = time.perf_counter()
            exact = garment_model.pose(x, art).vertices
            seconds["exact"] += time.perf_counter() - start
            start = time.perf_counter()
            parts = _tangents(fields, x, last)
            approx = torch.cat([garment_model.pose(x[p.frames], art[p.frames], p.tangent).vertices
                                for p in parts])  # fmt: skip
            seconds["linearized"] += time.perf_counter() - start
            made += sum(last is None or p.tangent is not last.tangent for p in parts)
            last = parts[-1]
            gaps.append(1e3 * (exact - approx).norm(dim=-1).numpy())
    gap = np.concatenate(gaps)
    p99 = np.quantile(gap, 0.99)
    print(f"{motion.num_frames} frames, chunks of {args.chunk}: linearized vs exact M_G, "
          f"mean {gap.mean():.3f} mm, p99 {p99:.3f} mm, max {gap.max():.3f} mm; "
          f"{made} linearizations")  # fmt: skip
    for name, value in seconds.items():
        print(f"  {name}: {value:.2f} s, {1e3 * value / motion.num_frames:.2f} ms per frame")
    print(f"  speed-up x{seconds['exact'] / seconds['linearized']:.1f}")


if __name__ == "__main__":
    main()
