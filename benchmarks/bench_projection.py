"""Benchmark of the projection of simulated garments to canonical space (the paper's Sec. 3.3),
against the two unposing baselines of its Fig. 5, measured in the same run.

Sequences: by default a few short T-shirt sequences simulated here (procedural motions × random
body shapes, Newton Style3D; cached under scratch/projection/ as .npz, so later runs only
project); with ``--manifest`` the ok sequences of a simulated dataset (``dataset make``), read from
its USD layers as ``usd-garment project`` reads them. With ``--canonical`` our projection is not
run again but read from a training set file written by ``usd-garment project`` over the same
layers (its throughput then comes from the file's metadata).

For each method it prints: mean and p99 reprojection error (m_sim vs the method's own forward
model, mm; zero by construction for the two baselines, whose inverse skinning is exact),
share of canonical vertices inside the canonical body and within 1 mm of it (exact signed
distance to the β = 0 T-pose body mesh), mean per-vertex acceleration of X in canonical space
(m/s², 30 fps: temporal stability), and throughput (frames/s on this CPU). The totals pool all
vertices of all frames.

    python benchmarks/bench_projection.py [--lod high] [--frames 60] [--iterations 40]
    python benchmarks/bench_projection.py --manifest scratch/dataset_tshirt_v2/manifest.json \
        --split validation,test [--max-sequences K] [--canonical set.npz]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.canonical.dataset import CanonicalSet, load_canonical_set
from usd_garment.canonical.project_layers import match_frames
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
from usd_garment.training.dataset import SPLITS, dataset_layers
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion

FPS = 30.0
CACHE = Path(__file__).resolve().parents[1] / "scratch" / "projection"
#: (motion kind, motion seed, shape seed; None: the mean shape).
SEQUENCES = (("arm_raise", 1, None), ("torso_twist", 2, 11), ("walk", 3, 12), ("arm_swing", 4, 13))
LEAD_IN = 10
METHODS = ("ours", "constant weights", "per-frame nearest vertex")
#: One sequence to measure: (label, motion at the garment's frames, points (T, N, 3), source).
Sequence = tuple[str, SmplMotion, np.ndarray, Path | None]


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


def simulated_sequences(body: BodyModel, lod: str, frames: int, count: int) -> Iterator[Sequence]:
    """The benchmark's own cached or newly simulated sequences (failed ones skipped)."""
    for kind, seed, shape_seed in SEQUENCES[:count]:
        started = time.perf_counter()
        motion, points = simulate(body, lod, kind, seed, shape_seed, frames)
        if motion is not None and points is not None:
            label = f"{kind} (shape seed {shape_seed})"
            print(f"{label}: {len(points)} frames, ready in {time.perf_counter() - started:.1f} s")
            yield label, motion, points, None


def dataset_sequences(
    manifest: Path, splits: list[str], max_sequences: int | None, body: BodyModel, n: int
) -> Iterator[Sequence]:
    """The ok sequences of a simulated dataset in ``splits``, read from their USD layers."""
    layers = dataset_layers(manifest, splits)
    chosen = list(zip(layers.names, layers.splits, layers.bodies, layers.garments, strict=True))
    chosen = chosen[:max_sequences]
    print(f"{manifest}: {len(chosen)} ok sequences of {'+'.join(splits)}")
    for name, split, body_layer, garment in chosen:
        points, _, layer = read_garment_layer(garment)
        if points.shape[1] != n:
            raise SystemExit(f"{garment}: {points.shape[1]} vertices, the template has {n}")
        motion, _ = read_smpl_motion(body_layer, body)
        yield f"{name} ({split})", match_frames(points, layer.time_codes, motion), points, garment


class Totals:
    """Figures of one method pooled over all vertices of all frames."""

    def __init__(self) -> None:
        self.vertices = 0
        self.inside = 0
        self.within_1mm = 0
        self.acc_sum = 0.0
        self.acc_count = 0
        self.errors: list[np.ndarray] = []
        self.seconds = 0.0

    def add(self, canonical: np.ndarray, error: np.ndarray, sdf: np.ndarray) -> dict[str, float]:
        """Add one sequence; its own figures."""
        acc = np.linalg.norm(canonical[2:] - 2 * canonical[1:-1] + canonical[:-2], axis=-1)
        acc *= FPS**2
        self.vertices += sdf.size
        self.inside += int((sdf < 0).sum())
        self.within_1mm += int((sdf < 1e-3).sum())
        self.acc_sum += float(acc.sum())
        self.acc_count += acc.size
        self.errors.append(error.astype(np.float32).ravel())
        return figures(sdf.size, int((sdf < 0).sum()), int((sdf < 1e-3).sum()),
                       float(acc.mean()), error.ravel())  # fmt: skip

    def pooled(self) -> dict[str, float]:
        acc = self.acc_sum / max(self.acc_count, 1)
        return figures(
            self.vertices, self.inside, self.within_1mm, acc, np.concatenate(self.errors)
        )


def figures(
    vertices: int, inside: int, within: int, acc: float, error: np.ndarray
) -> dict[str, float]:
    """Collision shares, acceleration and reprojection error figures of one method."""
    return {
        "inside": inside / vertices,
        "within_1mm": within / vertices,
        "acc": acc,
        "err_mean": float(error.mean()),
        "err_p99": float(np.percentile(error, 99)),
        "err_max": float(error.max()),
    }


def line(name: str, m: dict[str, float]) -> str:
    return (f"  {name:26s} err mean {1e3 * m['err_mean']:6.3f} mm p99 {1e3 * m['err_p99']:6.3f} "
            f"mm max {1e3 * m['err_max']:7.3f} mm | inside {100 * m['inside']:7.4f}% "
            f"<1 mm {100 * m['within_1mm']:7.3f}% | acc {m['acc']:6.3f} m/s²")  # fmt: skip


def stored_projection(data: CanonicalSet, source: Path) -> np.ndarray:
    """The canonical X ``(T, N, 3)`` of ``source``'s sequence in a training set file."""
    sources = [Path(p).resolve() for p in data.sources]
    if source.resolve() not in sources:
        raise SystemExit(f"{source}: not in the canonical set file")
    return data.canonical[data.sequence(sources.index(source.resolve()))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lod", default="high")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--iterations", type=int, default=ProjectionSettings.iterations)
    parser.add_argument("--chunk", type=int, default=ProjectionSettings.chunk)
    parser.add_argument("--sequences", type=int, default=len(SEQUENCES))
    parser.add_argument("--fields", default=None, help="body fields file (default: embedded)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--manifest", type=Path, default=None, help="simulated dataset manifest")
    parser.add_argument(
        "--split", default="test", help="with --manifest: comma-separated splits, or 'all'"
    )
    parser.add_argument("--max-sequences", type=int, default=None, help="with --manifest")
    parser.add_argument(
        "--canonical", type=Path, default=None,
        help="with --manifest: read our projection from this 'usd-garment project' output",
    )  # fmt: skip
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    body = load_body_model()
    template = load_template("tshirt", args.lod)
    draped = load_template("tshirt", args.lod, draped=True)
    model = GarmentModel(body, load_body_fields(args.fields))
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    settings = ProjectionSettings(iterations=args.iterations, chunk=args.chunk)
    stored = None if args.canonical is None else load_canonical_set(args.canonical)
    print(f"T-shirt {args.lod}: {len(template.vertices)} vertices; {settings}; "
          f"torch threads {torch.get_num_threads()}")  # fmt: skip
    if stored is not None:
        print(f"ours: read from {args.canonical} ({stored.metadata['projection']})")
    if args.manifest is None:
        sequences = simulated_sequences(body, args.lod, args.frames, args.sequences)
    else:
        splits = list(SPLITS) if args.split == "all" else args.split.split(",")
        sequences = dataset_sequences(
            args.manifest, splits, args.max_sequences, body, len(template.vertices)
        )
    totals = {name: Totals() for name in METHODS}
    rest_body = body.v_template.numpy()
    frames_total = 0
    for label, motion, points, source in sequences:
        print(label)
        frames_total += len(points)
        args_m = (motion.betas, motion.pose, motion.trans)
        runs = {}
        t0 = time.perf_counter()
        if stored is not None and source is not None:
            ours = stored_projection(stored, source)
        else:
            ours = project_sequence(model, template.vertices, template.faces, points, *args_m,
                                    settings, start=draped.vertices).canonical  # fmt: skip
        t1 = time.perf_counter()
        with torch.no_grad():
            again = model(torch.as_tensor(ours), *(torch.as_tensor(a) for a in args_m)).vertices
        runs["ours"] = (ours, np.linalg.norm(again.numpy() - points, axis=-1))
        const = unpose_constant_weights(body, template, points, *args_m)
        t2 = time.perf_counter()
        near = unpose_nearest_vertex(body, points, *args_m)
        t3 = time.perf_counter()
        for name, result in (("constant weights", const), ("per-frame nearest vertex", near)):
            again = skin_body_vertices(body, result.canonical, result.body_vertex, *args_m)
            runs[name] = (result.canonical, np.linalg.norm(again - points, axis=-1))
        for name, dt in zip(METHODS, (t1 - t0, t2 - t1, t3 - t2), strict=True):
            totals[name].seconds += dt
        for name, (canonical, error) in runs.items():
            rest = np.repeat(rest_body[None], len(canonical), axis=0)
            sdf = signed_distance(canonical, rest, surface).distance
            print(line(name, totals[name].add(canonical, error, sdf)))
    print(f"all {frames_total} frames, pooled over all vertices of all frames:")
    for name, total in totals.items():
        if stored is not None and name == "ours":
            seconds = float(stored.metadata["seconds"])
            wall = float(stored.metadata["wall_seconds"])
            rate = (
                f"{len(stored.canonical) / seconds:.2f} frames/s per worker, "
                f"{len(stored.canonical) / wall:.2f} frames/s wall with "
                f"{stored.metadata['workers']} worker(s), over the whole file"
            )
        else:
            rate = f"{frames_total / total.seconds:.2f} frames/s"
        print(f"{line(name, total.pooled())} | {rate}")


if __name__ == "__main__":
    main()
