"""Benchmark of the push-out post-process (``dress --quality final``, the ``+postprocess``
methods): the learned garment of a body layer pushed out of the posed body in this process (the
baseline) and by pools of worker processes (``dress --workers N``), in one run; the results must
be identical to the bit. Also times the learned garment itself (what ``+postprocess`` adds to)
and reports where one process spends its time per frame.

Run: ``python benchmarks/bench_push_out.py [BODY.usda] [--workers 2 4] [--frames A:B]``
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.eval.body_distance import BodyPool, BodySurface
from usd_garment.eval.push_out import push_out
from usd_garment.garment.library import load_template
from usd_garment.methods.learned import LearnedMethod
from usd_garment.usd.read import read_smpl_motion


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("body", nargs="?", default="examples/walk.usda")
    parser.add_argument("--workers", type=int, nargs="+", default=[2])
    parser.add_argument("--frames", default=None, help="A:B, frames A .. B-1")
    args = parser.parse_args()
    frames = tuple(int(v) for v in args.frames.split(":")) if args.frames else None

    body = load_body_model()
    motion, _ = read_smpl_motion(args.body, body, frames=frames)
    template = load_template("tshirt", "high")
    method = LearnedMethod()
    method.predict(motion, body, template)  # loads the model and the fields
    start = time.perf_counter()
    points = method.predict(motion, body, template)
    learned = time.perf_counter() - start
    with torch.no_grad():
        posed = body(
            torch.as_tensor(motion.betas, dtype=torch.float32),
            torch.as_tensor(motion.pose, dtype=torch.float32),
            torch.as_tensor(motion.trans, dtype=torch.float32),
        ).vertices.numpy()
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    count = len(points)
    print(f"{args.body}: {count} frames, {points.shape[1]} garment and {posed.shape[1]} body "
          f"vertices, {torch.get_num_threads()} torch threads")  # fmt: skip
    print(f"learned garment: {1e3 * learned / count:.2f} ms/frame ({count / learned:.0f} frames/s)")

    profiler = cProfile.Profile()
    start = time.perf_counter()
    reference = profiler.runcall(push_out, points, posed, surface)
    serial = time.perf_counter() - start
    moved = int((np.abs(reference - points).max(axis=-1) > 0).sum())
    print(f"push-out, this process: {1e3 * serial / count:.1f} ms/frame ({count / serial:.1f} "
          f"frames/s; {moved} vertex-frames moved)")  # fmt: skip
    for workers in args.workers:
        with BodyPool(workers) as pool:
            seconds = []
            for _ in range(2):  # cold (the workers start), then warm
                start = time.perf_counter()
                pushed = push_out(points, posed, surface, pool=pool)
                seconds.append(time.perf_counter() - start)
                if not np.array_equal(pushed, reference):
                    raise SystemExit(f"{workers} workers: not the single process's result")
        cold, warm = seconds
        print(f"push-out, {workers} workers: {1e3 * warm / count:.1f} ms/frame ({count / warm:.1f} "
              f"frames/s, x{serial / warm:.2f} the single process; {cold:.1f} s with the "
              "workers' start), identical to the bit")  # fmt: skip

    text = io.StringIO()
    stats = pstats.Stats(profiler, stream=text).sort_stats("tottime")
    stats.print_stats(8)
    print("where one process spends its time (tottime, whole run):")
    print("\n".join(line for line in text.getvalue().splitlines()[6:] if line.strip()))


if __name__ == "__main__":
    main()
