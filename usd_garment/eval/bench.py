"""Speed against accuracy: every garment method at every level of detail dressed on the same
inputs in one run, each result evaluated against the posed body (collisions by winding number)
and, where a simulated reference exists, against the simulation (mean vertex error)."""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from usd_garment.atomic import atomic_output
from usd_garment.body.io import load_body_model
from usd_garment.dress import dress
from usd_garment.eval.body_distance import BodyPool
from usd_garment.eval.evaluate import evaluate_layer
from usd_garment.eval.metrics import GarmentMetrics
from usd_garment.methods import GarmentMethod, get_method
from usd_garment.methods.learned import LEARNED_METHODS, learned_method
from usd_garment.usd.read import read_smpl_motion


@dataclass(frozen=True)
class BenchInput:
    """One animated body to dress.

    Attributes:
        name: the label in the report.
        body: the animated SMPL body layer.
        reference: a simulated garment layer of that body (any level of detail) to measure the
            error against; None when there is none.
    """

    name: str
    body: Path
    reference: Path | None = None


@dataclass(frozen=True)
class BenchMethod:
    """One method of the chart.

    Attributes:
        label: its name in the report (e.g. "learned", "learned no-self-supervision").
        method: the registry name of the garment method.
        model: the model directory of a learned method (None: the shipped default).
        lods: the levels of detail to run it at.
        frames: dress only the first ``frames`` frames of each input (None: all); for methods
            too slow to run whole inputs (the simulation).
    """

    label: str
    method: str
    model: Path | None = None
    lods: tuple[str, ...] = ("high",)
    frames: int | None = None

    def instance(self) -> GarmentMethod:
        """A new instance of the method."""
        if self.method in LEARNED_METHODS:
            return learned_method(self.method, self.model)
        return get_method(self.method)


@dataclass
class BenchRow:
    """One method × level of detail × input.

    Attributes:
        input, label, method, lod: what was run.
        frames, vertices: the size of the output.
        seconds: wall time (s) of read, compute and write inside the stage processor.
        frames_per_second: frames over the total of ``seconds``.
        summary: the sequence figures of :class:`GarmentMetrics` (``reference_mm``: against
            the reference carried to this level of detail; None without a reference).
        inside_elsewhere: ``(T,)`` per-frame share inside the body elsewhere.
        inside_forced: ``(T,)`` per-frame share inside where the body is pressed into itself.
        elsewhere_by_part: share of the vertex-frames inside elsewhere on each body part
            (:meth:`GarmentMetrics.elsewhere_by_part`); empty for none, and in reports written
            before stop 33.
        error: the failure's one-line message when the method failed on this input, else "".
    """

    input: str
    label: str
    method: str
    lod: str
    frames: int = 0
    vertices: int = 0
    seconds: dict[str, float] = field(default_factory=dict)
    frames_per_second: float = float("nan")
    summary: dict[str, Any] = field(default_factory=dict)
    inside_elsewhere: list[float] = field(default_factory=list)
    inside_forced: list[float] = field(default_factory=list)
    error: str = ""
    elsewhere_by_part: dict[str, float] = field(default_factory=dict)


#: Columns of the CSV table (summary figures after the run's own columns).
CSV_SUMMARY = (
    "inside_forced_share",
    "inside_elsewhere_share",
    "within_1mm_share",
    "max_elsewhere_mm",
    "reference_mm",
    "reference_shift_mm",
    "acceleration",
    "nan_count",
)


def run_bench(
    inputs: Sequence[BenchInput],
    methods: Sequence[BenchMethod],
    folder: str | Path,
    *,
    garment: str = "tshirt",
    on_row: Callable[[BenchRow], None] | None = None,
    pool: BodyPool | None = None,
) -> list[BenchRow]:
    """Dress every input with every method at each of its levels of detail and evaluate it;
    an input's reference simulation gets a row of its own (:data:`REFERENCE_LABEL`, no speed).

    Layers go to ``folder/layers``. A method that raises on an input gets a row with ``error``
    set and the run goes on (the stress suite wants to see failures, not stop at them).
    ``pool``: worker processes that measure the layers (the methods run, and are timed, in
    this process).

    Raises:
        FileNotFoundError: ``folder`` cannot be created.
    """
    layers = Path(folder) / "layers"
    layers.mkdir(parents=True, exist_ok=True)
    body = load_body_model() if any(m.frames is not None for m in methods) else None
    rows = []
    for case in inputs:
        length = read_smpl_motion(case.body, body)[0].num_frames if body is not None else 0
        if case.reference is not None:
            rows.append(_reference_row(case, garment, pool))
            if on_row is not None:
                on_row(rows[-1])
        for entry in methods:
            for lod in entry.lods:
                row = BenchRow(case.name, entry.label, entry.method, lod)
                out = layers / f"{case.name}__{entry.label.replace(' ', '_')}__{lod}.usdc"
                frames = None if entry.frames is None else (0, min(entry.frames, length))
                try:
                    result = dress(
                        case.body, out, garment=garment, method=entry.instance(), lod=lod,
                        frames=frames,
                    )  # fmt: skip
                    metrics, _ = evaluate_layer(out, case.body, case.reference, garment, pool=pool)
                except Exception as exc:  # a failing method is a result here, not the end
                    row.error = _failure(exc)
                else:
                    row.vertices, row.seconds = result.vertices, result.seconds
                    row.frames_per_second = result.frames / max(sum(result.seconds.values()), 1e-9)
                    _set_metrics(row, metrics, result.frames)
                rows.append(row)
                if on_row is not None:
                    on_row(row)
    return rows


#: The label of the rows that measure an input's reference simulation itself.
REFERENCE_LABEL = "simulation (reference)"


def _reference_row(case: BenchInput, garment: str, pool: BodyPool | None) -> BenchRow:
    """The figures of ``case``'s reference simulation itself (collisions, jitter; no speed:
    it was not run here)."""
    assert case.reference is not None
    row = BenchRow(case.name, REFERENCE_LABEL, "reference", "-")
    try:
        metrics, codes = evaluate_layer(case.reference, case.body, None, garment, pool=pool)
    except Exception as exc:  # an unreadable reference is reported like a failed method
        row.error = _failure(exc)
        return row
    _set_metrics(row, metrics, len(codes))
    return row


def _failure(exc: Exception) -> str:
    """The one-line ``error`` of a row: the exception's type and first line."""
    return f"{type(exc).__name__}: {(str(exc) or '-').splitlines()[0]}"


def _set_metrics(row: BenchRow, metrics: GarmentMetrics, frames: int) -> None:
    """Fill ``row``'s frame count, summary and per-frame collision curves from ``metrics``."""
    row.frames = frames
    row.summary = metrics.summary()
    row.inside_elsewhere = [float(v) for v in metrics.inside_elsewhere_share]
    row.inside_forced = [float(v) for v in metrics.inside_forced_share]
    row.elsewhere_by_part = metrics.elsewhere_by_part()


@dataclass
class ChartPoint:
    """One method × level of detail over all inputs: frames/s over all frames, collision and
    error figures as frame-weighted means over the inputs it ran on."""

    label: str
    lod: str
    frames: int
    frames_per_second: float
    inside_elsewhere_share: float
    inside_forced_share: float
    within_1mm_share: float
    reference_mm: float
    reference_shift_mm: float
    acceleration: float
    failures: int


def chart_points(rows: Sequence[BenchRow]) -> list[ChartPoint]:
    """The rows gathered per method × level of detail, in the order they first appear."""
    keys = list(dict.fromkeys((r.label, r.lod) for r in rows))
    points = []
    for label, lod in keys:
        ok = [r for r in rows if (r.label, r.lod) == (label, lod) and not r.error]
        frames = sum(r.frames for r in ok)
        seconds = sum(sum(r.seconds.values()) for r in ok)

        def mean(key: str, group: list[BenchRow] = ok) -> float:
            pairs = [(r.summary.get(key), r.frames) for r in group]
            pairs = [(v, n) for v, n in pairs if v is not None and np.isfinite(v)]
            if not pairs:
                return float("nan")
            return float(sum(v * n for v, n in pairs) / sum(n for _, n in pairs))

        points.append(
            ChartPoint(
                label=label,
                lod=lod,
                frames=frames,
                frames_per_second=frames / seconds if seconds > 0 else float("nan"),
                inside_elsewhere_share=mean("inside_elsewhere_share"),
                inside_forced_share=mean("inside_forced_share"),
                within_1mm_share=mean("within_1mm_share"),
                reference_mm=mean("reference_mm"),
                reference_shift_mm=mean("reference_shift_mm"),
                acceleration=mean("acceleration"),
                failures=sum(1 for r in rows if (r.label, r.lod) == (label, lod) and r.error),
            )
        )
    return points


def simulated_rows(rows: Sequence[BenchRow]) -> list[BenchRow]:
    """The rows of the inputs that have a reference simulation (the frames every figure of the
    paper's Table 1, error included, is measured on; an input without one adds collisions and
    jitter but no error to a chart point)."""
    simulated = {r.input for r in rows if r.label == REFERENCE_LABEL and not r.error}
    return [r for r in rows if r.input in simulated]


def chart_table(rows: Sequence[BenchRow]) -> str:
    """The chart points as a plain-text table (the paper's Table 1 with speed and error):
    shares in % of vertices, error and the whole garment's mean offset in mm, jitter as mean
    vertex acceleration in m/s²."""
    head = (f"{'method':<30} {'lod':<6} {'frames':>6} {'frames/s':>9} {'forced %':>9} "
            f"{'elsewhere %':>11} {'<1 mm %':>8} {'error mm':>8} {'offset':>6} {'accel':>6} "
            "failed")  # fmt: skip
    lines = [head]
    for p in chart_points(rows):
        lines.append(
            f"{p.label:<30} {p.lod:<6} {p.frames:>6} {p.frames_per_second:>9.1f} "
            f"{100 * p.inside_forced_share:>9.4f} {100 * p.inside_elsewhere_share:>11.4f} "
            f"{100 * p.within_1mm_share:>8.3f} {p.reference_mm:>8.2f} "
            f"{p.reference_shift_mm:>6.2f} {p.acceleration:>6.2f} {p.failures}"
        )
    return "\n".join(lines)


def pareto_front(speed: Sequence[float], cost: Sequence[float]) -> list[int]:
    """Indices of the points no other point beats: none is at least as fast and at most as
    costly with one of the two strictly better (NaN points are never on the front); sorted by
    speed."""
    ok = [i for i in range(len(speed)) if np.isfinite(speed[i]) and np.isfinite(cost[i])]
    front = [
        i
        for i in ok
        if not any(
            speed[j] >= speed[i]
            and cost[j] <= cost[i]
            and (speed[j], cost[j]) != (speed[i], cost[i])
            for j in ok
        )
    ]
    return sorted(front, key=lambda i: speed[i])


def write_report(
    rows: Sequence[BenchRow], folder: str | Path, extra: dict[str, Any] | None = None
) -> tuple[Path, Path]:
    """Write ``report.json`` (rows with per-frame curves, chart points, ``extra``) and
    ``report.csv`` (one line per row) to ``folder``; returns both paths."""
    folder = Path(folder)
    points = chart_points(rows)
    payload = {
        "rows": [asdict(r) for r in rows],
        "chart": [asdict(p) for p in points],
        "written": time.strftime("%Y-%m-%d %H:%M:%S"),
        **(extra or {}),
    }
    json_path, csv_path = folder / "report.json", folder / "report.csv"
    with atomic_output(json_path) as tmp:
        tmp.write_text(json.dumps(_finite(payload), indent=1))
    with atomic_output(csv_path) as tmp, open(tmp, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(
            ["input", "method", "lod", "frames", "vertices", "frames_per_second", "read_s",
             "compute_s", "write_s", *CSV_SUMMARY, "error", "elsewhere_parts"]
        )  # fmt: skip
        for r in rows:
            s = r.seconds
            writer.writerow(
                [r.input, r.label, r.lod, r.frames, r.vertices, _cell(r.frames_per_second),
                 *(_cell(s.get(k)) for k in ("read", "compute", "write")),
                 *(_cell(r.summary.get(k)) for k in CSV_SUMMARY), r.error,
                 _parts_cell(r.elsewhere_by_part)]
            )  # fmt: skip
    return json_path, csv_path


#: Body parts named in a CSV row's ``elsewhere_parts`` cell, largest share first.
CSV_PARTS = 3


def _parts_cell(parts: dict[str, float]) -> str:
    """``"spine2 61.1%; left_shoulder 20.6%; ..."``: the largest :data:`CSV_PARTS` shares."""
    return "; ".join(f"{name} {share:.1%}" for name, share in list(parts.items())[:CSV_PARTS])


def load_report(path: str | Path) -> list[BenchRow]:
    """The rows of a ``report.json`` that :func:`write_report` wrote (None read back as NaN).

    Raises:
        ValueError: not a bench report.
    """
    try:
        payload = json.loads(Path(path).read_text(encoding="utf-8"))
        rows = [BenchRow(**row) for row in payload["rows"]]
    except (OSError, KeyError, TypeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a bench report ({exc})") from exc
    for row in rows:
        if row.frames_per_second is None:
            row.frames_per_second = float("nan")
        row.summary = {k: (float("nan") if v is None else v) for k, v in row.summary.items()}
    return rows


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def _finite(value: Any) -> Any:
    """``value`` with NaN and infinite floats replaced by None (valid JSON)."""
    if isinstance(value, float):
        return value if np.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
