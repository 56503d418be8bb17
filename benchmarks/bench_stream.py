"""Benchmark of the streaming stage processor: ``dress`` of long animations with the whole
sequence computed and written at once (``frames_per_chunk`` = the length: the processor as it was
before streaming) against chunks of 256 frames (the default), in one run. Each run is a fresh
process, so its peak resident memory is its own; times are inside the processor (read, compute,
write), without interpreter start. A cProfile of the streamed run of the first length shows where
the time goes.

Run: ``python benchmarks/bench_stream.py [--frames 1000 4000 10000] [--method learned]``
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_dress import procedural_npz

from usd_garment.body import load_body_model
from usd_garment.dress import FRAMES_PER_CHUNK
from usd_garment.methods.learned import default_method
from usd_garment.motion.amass import load_amass
from usd_garment.usd.body_layer import write_body_layer

RUN = """
import json, resource, sys
from usd_garment.dress import dress
r = dress(sys.argv[1], sys.argv[2], method=sys.argv[3], frames_per_chunk=int(sys.argv[4]))
out = r.to_json()
out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps(out))
"""


def run(body: Path, out: Path, method: str, chunk: int) -> dict:
    """One ``dress`` in a fresh interpreter; its summary with ``peak_rss_mb``."""
    done = subprocess.run(
        [sys.executable, "-c", RUN, str(body), str(out), method, str(chunk)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.splitlines()[-1])


def profile(body: Path, out: Path, method: str) -> str:
    """The top of a cProfile of a streamed ``dress`` (cumulative time)."""
    from usd_garment.dress import dress

    profiler = cProfile.Profile()
    profiler.runcall(dress, body, out, method=method)
    text = io.StringIO()
    pstats.Stats(profiler, stream=text).sort_stats("cumulative").print_stats(18)
    return text.getvalue()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, nargs="+", default=[1000, 4000, 10000])
    parser.add_argument("--method", default=default_method("tshirt", "high"))
    parser.add_argument("--no-profile", action="store_true")
    args = parser.parse_args()
    body_model = load_body_model()
    print(f"method {args.method}, T-shirt high, chunks of {FRAMES_PER_CHUNK} frames")
    print(f"{'frames':>7} {'mode':<10} {'frames/s':>9} {'read s':>7} {'compute s':>9} "
          f"{'write s':>8} {'peak MB':>8}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for frames in args.frames:
            npz, body = folder / f"walk{frames}.npz", folder / f"walk{frames}.usdc"
            procedural_npz(npz, frames)
            write_body_layer(body, load_amass(npz, body_model), body_model)
            results = {}
            for mode, chunk in (("whole", frames), ("streamed", FRAMES_PER_CHUNK)):
                r = run(body, folder / f"{mode}{frames}.usdc", args.method, chunk)
                s, fps, peak = r["seconds"], r["frames_per_second"], r["peak_rss_mb"]
                results[mode] = r
                print(f"{frames:>7} {mode:<10} {fps:>9.1f} {s['read']:>7.2f} "
                      f"{s['compute']:>9.2f} {s['write']:>8.2f} {peak:>8.0f}")  # fmt: skip
            w, st = results["whole"], results["streamed"]
            speed = st["frames_per_second"] / w["frames_per_second"]
            memory = st["peak_rss_mb"] / w["peak_rss_mb"]
            print(f"{frames:>7} ratio      speed x{speed:.2f}, peak memory x{memory:.2f} "
                  "(streamed / whole)")  # fmt: skip
        if not args.no_profile:
            first = args.frames[0]
            print(profile(folder / f"walk{first}.usdc", folder / "profiled.usdc", args.method))


if __name__ == "__main__":
    main()
