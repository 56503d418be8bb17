"""Tuning bench of ``learned+preimage``'s push (``usd_garment/canonical/preimage_push.py``): for
each setting of its constants (passes, step bound, fixed-point steps) and, optionally, of the
margin the pushed vertices end at outside the canonical body (mm; default: the method's
``PUSH_OUT_EPS``), the inside share of each
``--layer`` (forced / elsewhere, winding number against the posed body, as ``usd-garment eval``
counts it) and the push's time per frame on ``--speed-layer`` (default: the first layer), the
fastest of ``--repeat`` runs, with its ratio to the first setting's in the same run.

Each layer is dressed once with ``learned+preimage`` (the shipped T-shirt, high level of detail)
with the push's inputs recorded; every setting then pushes those inputs again, with the module's
constants set for its row and put back after it (stop 46's session script left them set, so that
later rows ran with earlier rows' changes). The first setting is the shipped one unless
``--setting`` is given; stop 48 chose its setting with this grid by a rule written before the
runs (``docs/learning.md``, "The preimage search with the arms as captured").

Run: ``python benchmarks/tune_preimage.py --layer A.usdc [--layer B.usdc ...]
[--speed-layer W.usdc] [--setting PASSES,BOUND,STEPS[,MARGIN_MM] ...] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import usd_garment.methods.learned as learned
from usd_garment.body import load_body_model
from usd_garment.canonical import preimage_push as search
from usd_garment.dress import dress
from usd_garment.eval.body_distance import BodyFrames, BodySurface, signed_distance
from usd_garment.eval.evaluate import posed_body_vertices
from usd_garment.fields.body_fields import BodyFields, load_body_fields
from usd_garment.methods import get_method
from usd_garment.usd.read import read_smpl_motion

#: The constants a setting sets, in the order of ``--setting``.
CONSTANTS = ("PASSES", "STEP_BOUND", "PREIMAGE_STEPS")


@dataclass
class PushInputs:
    """One call of :func:`preimage_push` (a chunk of frames): its arguments but the fields."""

    points: torch.Tensor
    own: torch.Tensor
    transforms: torch.Tensor
    betas: torch.Tensor
    boxes: search.PartBoxes
    epsilon: float


def record(layer: Path) -> list[PushInputs]:
    """The push's inputs, chunk by chunk, of dressing ``layer`` with ``learned+preimage``."""
    calls: list[PushInputs] = []
    original = learned.preimage_push

    def recording(
        points: torch.Tensor,
        own: torch.Tensor,
        transforms: torch.Tensor,
        fields: BodyFields,
        betas: torch.Tensor,
        boxes: search.PartBoxes,
        epsilon: float,
    ) -> torch.Tensor:
        calls.append(PushInputs(points.clone(), own.clone(), transforms.clone(), betas.clone(),
                                boxes, epsilon))  # fmt: skip
        return original(points, own, transforms, fields, betas, boxes, epsilon)

    learned.preimage_push = recording
    try:
        with tempfile.TemporaryDirectory() as tmp:
            dress(layer, Path(tmp) / "garment.usdc", method=get_method("learned+preimage"))
    finally:
        learned.preimage_push = original
    return calls


@contextmanager
def setting(values: tuple[float, ...]) -> Iterator[None]:
    """The module's constants set to ``values`` (see :data:`CONSTANTS`), put back after."""
    saved = {name: getattr(search, name) for name in CONSTANTS}
    try:
        for name, value in zip(CONSTANTS, values, strict=True):
            setattr(search, name, type(saved[name])(value))
        yield
    finally:
        for name, value in saved.items():
            setattr(search, name, value)


def push(calls: list[PushInputs], fields: BodyFields, margin: float | None = None) -> np.ndarray:
    """The pushed garments ``(T, N, 3)`` of every chunk, with the module's current constants,
    ending ``margin`` (m; None: the recorded one) outside the canonical body."""
    return torch.cat([
        search.preimage_push(c.points, c.own, c.transforms, fields, c.betas, c.boxes,
                             c.epsilon if margin is None else margin)
        for c in calls
    ]).numpy()  # fmt: skip


def split(values: tuple[float, ...]) -> tuple[tuple[float, ...], float | None]:
    """A setting's constants and its margin (m), None where it gives none."""
    constants = values[: len(CONSTANTS)]
    return constants, values[len(CONSTANTS)] * 1e-3 if len(values) > len(CONSTANTS) else None


def parse_setting(text: str) -> tuple[float, ...]:
    values = tuple(float(v) for v in text.split(","))
    if len(values) not in (len(CONSTANTS), len(CONSTANTS) + 1):
        raise argparse.ArgumentTypeError(f"{text!r}: give {','.join(CONSTANTS)}[,MARGIN_MM]")
    return values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layer", type=Path, action="append", required=True)
    parser.add_argument("--speed-layer", type=Path)
    parser.add_argument("--setting", type=parse_setting, action="append", default=[],
                        metavar=",".join(CONSTANTS) + "[,MARGIN_MM]")  # fmt: skip
    parser.add_argument("--repeat", type=int, default=3, help="timed runs; the fastest counts")
    args = parser.parse_args()
    settings = args.setting or [tuple(float(getattr(search, n)) for n in CONSTANTS)]
    body = load_body_model()
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    fields = load_body_fields()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    accuracy = []  # (layer, recorded push inputs, posed body, its search structures)
    for layer in args.layer:
        start = time.perf_counter()
        motion, _ = read_smpl_motion(layer, body)
        vertices = posed_body_vertices(body, motion)
        accuracy.append((layer, record(layer), vertices, BodyFrames(vertices, surface)))
        print(f"recorded {layer} ({motion.num_frames} frames) in "
              f"{time.perf_counter() - start:.1f} s")  # fmt: skip
    timed = record(args.speed_layer) if args.speed_layer else accuracy[0][1]
    frames = sum(len(c.points) for c in timed)
    best = [float("inf")] * len(settings)
    for _ in range(args.repeat):  # settings interleaved, so that drifts in speed hit all alike
        for i, values in enumerate(settings):
            constants, margin = split(values)
            with setting(constants):
                start = time.perf_counter()
                push(timed, fields, margin)
                best[i] = min(best[i], time.perf_counter() - start)
    names = "".join(f"{row[0].name[:24]:>26s}" for row in accuracy)
    print(f"{'passes, bound, steps[, mm]':26s}{names}   push ms/frame (x first)")
    for i, values in enumerate(settings):
        cells = []
        constants, margin = split(values)
        with setting(constants):
            for _, calls, vertices, structures in accuracy:
                pushed = push(calls, fields, margin)
                query = signed_distance(pushed, vertices, surface, frames=structures)
                cells.append(
                    f"{100 * query.forced.mean():.3f} / {100 * query.elsewhere.mean():.3f} %"
                )
        label = ", ".join(f"{v:g}" for v in values)
        print(f"{label:26s}" + "".join(f"{c:>26s}" for c in cells)
              + f"   {1e3 * best[i] / frames:.2f} ({best[i] / best[0]:.2f})")  # fmt: skip


if __name__ == "__main__":
    main()
