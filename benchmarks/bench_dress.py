"""Benchmark of the stage processor on a 1,000-frame 30 fps procedural animation: ``dress`` with
the default method (``learned+preimage`` where a model ships: the networks' garment pushed out
of the canonical body, then out of the parts posing carries it into), with ``learned`` (the
networks alone), with ``learned+canonical`` (only the canonical push) and with ``lbs``,
in-process (read, compute, write; the learned methods' stages in ms per frame: model loading,
pose code and GRU, decoder, canonical push-out, fields, posing, preimage push-out) and first
through the CLI, ``--cli-repeat`` times (3; with the interpreter's start; ``--cli-method`` gives
them a method, e.g. ``learned``); ``learned+postprocess`` (``dress --quality final``),
``lbs+postprocess`` and the physics simulation on slices of the same animation; the ratios
between them.

``--model LABEL=DIR`` (repeatable) also dresses the walk in-process with the learned method and
that model directory, e.g. to weigh an ensemble against the shipped model in the same run.

``--lods LOD ...`` (medium low) also dresses the walk in process with the default method at those
coarser levels of detail (where ``learned+preimage`` pushes the vertices it writes), with their
ratios to high; ``--cli-lod LOD`` gives the CLI runs a ``--lod``. ``--variants`` also dresses it in
process with the default method writing every coarser level as a ``lod`` variant
(``dress --lod-variants``: where the method pushes vertices out, each level dressed at its own),
with its ratio to the plain layer.

``--workers N`` also dresses the walk in process with ``learned+preimage`` posing and pushing
each chunk in N forked worker processes (``dress --workers N``; at most one for every two
chunks), with its ratio to one process, and gives the CLI runs ``--workers N``.

The in-process runs keep the memory they free, as ``usd-garment`` does (``cli/allocator.py``).

``--repeat N`` dresses in-process N times with each method and reports the fastest run (this
machine's speed varies by tens of per cent from one run to the next).

``--body LAYER`` dresses that body layer instead of the procedural walk: a real capture, e.g.
one imported with ``usd-garment import-bvh … --arm-clearance 0`` (the arms as captured, where
``learned+preimage`` has the most to push).

``--betas B1,B2,...`` dresses a body of that shape in every run (``dress --betas``): the walk
and the BVH imports have the template shape (β = 0), for which the preimage search looks up no
shape offsets.

Run: ``python benchmarks/bench_dress.py [--frames 1000 | --body LAYER] [--betas B1,B2,...]
[--postprocess-frames 100]
[--simulation-frames 30] [--model LABEL=DIR ...] [--repeat N] [--cli-repeat N]
[--cli-method METHOD] [--cli-lod LOD] [--lods LOD ...] [--variants] [--workers N]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import click
import numpy as np

from usd_garment.body import load_body_model
from usd_garment.cli.allocator import keep_freed_memory
from usd_garment.cli.options import parse_betas
from usd_garment.dress import dress
from usd_garment.eval.machine import describe_machine, speed_readings
from usd_garment.methods import GarmentMethod, get_method
from usd_garment.methods.learned import LearnedMethod, default_method
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


def per_frame(stages: dict[str, float], summary: dict) -> None:
    """The learned method's stages and the processor's read and write in ms per frame."""
    frames = summary["frames"]
    times = {**{k: v for k, v in stages.items() if v > 0}, "read": summary["seconds"]["read"],
             "write (normals, extents, USD)": summary["seconds"]["write"]}  # fmt: skip
    print("  ms per frame: " + ", ".join(f"{k} {1e3 * v / frames:.3f}" for k, v in times.items()))


def fastest(
    make: Callable[[], GarmentMethod], body_usd: Path, output: Path, repeat: int,
    lod: str = "high", variants: bool = False, betas: np.ndarray | None = None,
) -> tuple[dict, GarmentMethod]:  # fmt: skip
    """The summary of the fastest of ``repeat`` dresses of ``body_usd`` (shaped by ``betas``
    where given) at level of detail ``lod`` (with every coarser level as a ``lod`` variant where
    ``variants``), each by a new method instance from ``make`` (model loading included), and
    that run's instance."""
    best: tuple[dict, GarmentMethod] | None = None
    for _ in range(repeat):
        instance = make()
        summary = dress(body_usd, output, method=instance, lod=lod, lod_variants=variants,
                        betas=betas)  # fmt: skip
        summary = summary.to_json()
        if best is None or sum(summary["seconds"].values()) < sum(best[0]["seconds"].values()):
            best = (summary, instance)
    assert best is not None
    return best


def with_workers(workers: int) -> GarmentMethod:
    """``learned+preimage`` that poses and pushes in ``workers`` forked processes."""
    method = get_method("learned+preimage")
    assert isinstance(method, LearnedMethod)
    method.workers = workers
    return method


def cli_runs(
    body_usd: Path, folder: Path, repeat: int, method: str | None, lod: str | None,
    betas: str | None, workers: int,
) -> None:  # fmt: skip
    """``usd-garment dress`` (``--method method``, ``--lod lod``, ``--betas betas``; None: the
    defaults; ``--workers workers``) in a new interpreter ``repeat`` times: the stage
    processor's own figures and the wall time with the interpreter's start and imports; then
    the median and the fastest run.
    Run before anything else writes to disk (a run right after the in-process dresses, which
    write ~150 MB, measured 25-40 % slower)."""
    walls = []
    for i in range(repeat):
        start = time.perf_counter()
        cli = subprocess.run(
            [str(Path(sys.executable).with_name("usd-garment")), "dress", str(body_usd),
             "-o", str(folder / f"cli{i}.usdc"), "--json",
             *(["--method", method] if method else []), *(["--lod", lod] if lod else []),
             *(["--betas", betas] if betas else []), "--workers", str(workers)],
            capture_output=True, text=True, check=True,
        )  # fmt: skip
        walls.append(time.perf_counter() - start)
        summary = json.loads(cli.stdout)
        frames = summary["frames"]
        label = f"{method or 'default method'}{f' --lod {lod}' if lod else ''}"
        label += f" --workers {workers}" if workers > 1 else ""
        report(f"CLI run {i + 1}, {label}", summary)
        print(f"CLI run {i + 1} wall time incl. interpreter start: {walls[-1]:.2f} s, "
              f"{frames / walls[-1]:.1f} frames/s")  # fmt: skip
        (folder / f"cli{i}.usdc").unlink()
    if not walls:
        return
    print(f"CLI incl. interpreter start over {repeat} runs: median {frames / np.median(walls):.1f}"
          f" frames/s, fastest {frames / min(walls):.1f}")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1000, help="of the procedural walk")
    parser.add_argument("--body", type=Path, help="a body layer to dress instead of the walk")
    parser.add_argument("--betas", help="shape coefficients of the body in every run, e.g. 1,-0.5")
    parser.add_argument("--postprocess-frames", type=int, default=100)
    parser.add_argument("--simulation-frames", type=int, default=30)
    parser.add_argument("--model", action="append", default=[], metavar="LABEL=DIR")
    parser.add_argument("--repeat", type=int, default=1, help="in-process runs; the fastest counts")
    parser.add_argument("--cli-repeat", type=int, default=3, help="runs of the CLI command")
    parser.add_argument("--cli-method", help="the CLI runs' --method (default: none given)")
    parser.add_argument("--cli-lod", help="the CLI runs' --lod (default: none given)")
    parser.add_argument("--lods", nargs="*", default=["medium", "low"],
                        help="coarser levels the default also dresses in process")  # fmt: skip
    parser.add_argument("--variants", action="store_true",
                        help="also dress in process with --lod-variants")  # fmt: skip
    parser.add_argument("--workers", type=int, default=1,
                        help="also dress with learned+preimage's posing workers")  # fmt: skip
    args = parser.parse_args()
    try:
        betas = parse_betas(args.betas)
    except click.BadParameter as error:
        parser.error(f"--betas: {error.message}")
    # In process as in the command: freed memory kept (cli/allocator.py); without it the
    # default ran at 0.92-0.95 times the frames a second in process (stop 96, the walk).
    kept = keep_freed_memory()
    readings = ", ".join(f"{k} {v:.3g}" for k, v in speed_readings().items())
    print(f"{describe_machine()}; speed readings: {readings}; "
          f"freed memory kept as by the command: {'yes' if kept else 'no'}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        body_usd = args.body
        if body_usd is None:
            npz, body_usd = folder / "walk.npz", folder / "walk.usdc"
            start = time.perf_counter()
            procedural_npz(npz, args.frames)
            body = load_body_model()
            write_body_layer(body_usd, load_amass(npz, body), body)
            print(f"built {args.frames}-frame body layer in {time.perf_counter() - start:.1f} s")

        default = default_method("tshirt", "high")
        cli_runs(body_usd, folder, args.cli_repeat, args.cli_method, args.cli_lod, args.betas,
                 args.workers)  # fmt: skip
        runs = {}
        best = f", fastest of {args.repeat} runs" if args.repeat > 1 else ""
        in_process = (default, "learned", "learned+canonical", "learned+preimage", "lbs")
        for method in dict.fromkeys(in_process):
            runs[method], instance = fastest(lambda m=method: get_method(m), body_usd,
                                             folder / f"{method}.usdc", args.repeat,
                                             betas=betas)  # fmt: skip
            report(f"{method} (in-process{best})", runs[method])
            if isinstance(instance, LearnedMethod):
                per_frame(instance.seconds, runs[method])
        pooled = f"learned+preimage --workers {args.workers}"
        if args.workers > 1:
            runs[pooled], instance = fastest(lambda: with_workers(args.workers), body_usd,
                                             folder / "workers.usdc", args.repeat,
                                             betas=betas)  # fmt: skip
            report(f"{pooled} (in-process{best})", runs[pooled])
            per_frame(instance.seconds, runs[pooled])
        for lod in args.lods:
            label = f"{default} --lod {lod}"
            runs[label], instance = fastest(lambda: get_method(default), body_usd,
                                            folder / f"{lod}.usdc", args.repeat, lod,
                                            betas=betas)  # fmt: skip
            report(f"{label} (in-process{best})", runs[label])
            if isinstance(instance, LearnedMethod):
                per_frame(instance.seconds, runs[label])
        if args.variants:
            label = f"{default} --lod-variants"
            output = folder / "variants.usdc"
            runs[label], _ = fastest(lambda: get_method(default), body_usd, output, args.repeat,
                                     variants=True, betas=betas)  # fmt: skip
            report(f"{label} (in-process{best})", runs[label])
        models = [text.partition("=")[::2] for text in args.model]  # (label, directory)
        for label, path in models:
            runs[label], instance = fastest(lambda p=path: LearnedMethod(p), body_usd,
                                            folder / "model.usdc", args.repeat,
                                            betas=betas)  # fmt: skip
            report(f"{label}: learned with {path} (in-process{best})", runs[label])
            per_frame(instance.seconds, runs[label])
        slices = {
            "learned+postprocess": args.postprocess_frames,
            "lbs+postprocess": args.postprocess_frames,
            "simulation": args.simulation_frames,
        }
        frames = runs[default]["frames"]
        for method, count in slices.items():
            n = min(count, frames)
            runs[method] = dress(body_usd, folder / f"{method}.usdc", method=method,
                                 frames=(0, n), betas=betas).to_json()  # fmt: skip
            report(f"{method} (in-process, first {n} frames)", runs[method])
        fps = {m: r["frames"] / sum(r["seconds"].values()) for m, r in runs.items()}
        for method in [label for label, _ in models] + list(slices):
            print(f"ratio: {default} is {fps[default] / fps[method]:.1f}x faster end to end than "
                  f"{method}")  # fmt: skip
        for lod in args.lods:
            ratio = fps[f"{default} --lod {lod}"] / fps[default]
            print(f"ratio: {default} --lod {lod} is {ratio:.2f}x faster end to end than at high")
        if args.variants:
            ratio = fps[default] / fps[f"{default} --lod-variants"]
            print(f"ratio: {default} with --lod-variants takes {ratio:.2f}x the time of the plain "
                  "layer")  # fmt: skip
        if args.workers > 1:
            ratio = fps[pooled] / fps["learned+preimage"]
            print(f"ratio: {pooled} is {ratio:.2f}x faster end to end than in one process")
        if default != "learned":
            print(f"ratio: learned (the networks alone) is {fps['learned'] / fps[default]:.2f}x "
                  f"faster end to end than {default}")  # fmt: skip
        if default != "learned+preimage":
            print("ratio: learned+preimage is "
                  f"{fps['learned+preimage'] / fps['learned+postprocess']:.1f}x faster end to end "
                  "than learned+postprocess")  # fmt: skip


if __name__ == "__main__":
    main()
