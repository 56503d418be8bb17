"""Model no more than a scene needs: the fastest garment method × level of detail whose error
against the simulation, measured on held-out motion by ``usd-garment bench``, fits a budget in
millimetres.

The figures come from a bench report (``budget.json`` in the report folder, one entry per method
× level of detail: frame-weighted means over the inputs that have a simulated reference); a
model directory ships the table measured with its model, so ``dress --error-budget MM`` picks
from it without running anything. A table whose learned entries were measured with a model
names it (``source["model"]``: version and weights digest); a model directory of another version
or other weights is refused, so a retrained model never picks from its predecessor's figures, nor
a new version of the same networks (e.g. one that smooths its garment) from its own.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from usd_garment.atomic import atomic_output
from usd_garment.eval.bench import REFERENCE_LABEL, BenchRow, chart_points
from usd_garment.methods import available_methods
from usd_garment.methods.learned import shipped_model
from usd_garment.methods.learned_model import model_identity

#: The table's file name, in a bench report folder and in a model directory.
BUDGET_FILE = "budget.json"
FORMAT_VERSION = 1


class BudgetError(ValueError):
    """No table, a broken one, or no entry that meets the budget."""


@dataclass(frozen=True)
class BudgetEntry:
    """One method × level of detail on the bench's held-out inputs.

    Attributes:
        method: the registry name of the garment method.
        lod: the level of detail.
        error_mm: mean vertex distance to the simulation (mm).
        inside_elsewhere_share: share of vertices inside the body, not forced (0..1).
        frames_per_second: end-to-end speed inside the stage processor on the bench.
    """

    method: str
    lod: str
    error_mm: float
    inside_elsewhere_share: float
    frames_per_second: float


def budget_table(rows: Sequence[BenchRow]) -> list[BudgetEntry]:
    """The entries of a bench run: each registered method (not the ablations under other labels,
    not the reference) × level of detail with a finite error and speed."""
    methods = set(available_methods())
    entries = []
    for p in chart_points(rows):
        finite = math.isfinite(p.reference_mm) and math.isfinite(p.frames_per_second)
        if p.label in methods and p.label != REFERENCE_LABEL and finite:
            entries.append(
                BudgetEntry(p.label, p.lod, p.reference_mm, p.inside_elsewhere_share,
                            p.frames_per_second)
            )  # fmt: skip
    return entries


def save_budget(path: str | Path, entries: Sequence[BudgetEntry], source: dict[str, Any]) -> None:
    """Write the table with ``source`` (what measured it: command, inputs, machine)."""
    out = {"version": FORMAT_VERSION, "source": source, "entries": [asdict(e) for e in entries]}
    with atomic_output(Path(path)) as tmp:
        tmp.write_text(json.dumps(out, indent=1) + "\n")


def load_budget(path: str | Path) -> list[BudgetEntry]:
    """Read a table written by :func:`save_budget`.

    Raises:
        BudgetError: missing, unreadable or of another version.
    """
    return _read_table(Path(path))[0]


def _read_table(path: Path) -> tuple[list[BudgetEntry], dict[str, Any]]:
    """The entries and the source of the table at ``path`` (see :func:`load_budget`)."""
    if not path.is_file():
        raise BudgetError(
            f"{path}: no error table (make one with 'usd-garment bench ... -o DIR': "
            f"DIR/{BUDGET_FILE})"
        )
    try:
        data = json.loads(path.read_text())
        version, rows, source = data.get("version"), data["entries"], data.get("source", {})
        entries = [BudgetEntry(**e) for e in rows] if version == FORMAT_VERSION else None
        if not isinstance(source, dict):
            raise TypeError("source is not a mapping")
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise BudgetError(f"{path}: not an error table ({exc})") from exc
    if entries is None:
        raise BudgetError(f"{path}: error table version {version} not supported")
    return entries, source


def pick(entries: Sequence[BudgetEntry], error_mm: float) -> BudgetEntry:
    """The fastest entry whose error is at most ``error_mm``.

    Raises:
        BudgetError: none meets it (the message names the most accurate one).
    """
    meeting = [e for e in entries if e.error_mm <= error_mm]
    if not meeting:
        if not entries:
            raise BudgetError("the error table is empty")
        best = min(entries, key=lambda e: e.error_mm)
        raise BudgetError(
            f"no method meets an error of {error_mm:g} mm on the held-out motions (the most "
            f"accurate: {best.method} at {best.lod}, {best.error_mm:.1f} mm)"
        )
    return max(meeting, key=lambda e: e.frames_per_second)


def pick_for_budget(garment: str, model: str | Path | None, error_mm: float) -> BudgetEntry:
    """:func:`pick` from the table of ``model`` (a model directory; None: the shipped model of
    ``garment``).

    Raises:
        BudgetError: no model, no table, a table measured with another version or other
            weights than the model's, or nothing meets the budget.
    """
    folder = Path(model) if model is not None else shipped_model(garment)
    if folder is None:
        raise BudgetError(f"no model ships for the garment '{garment}', so no error table")
    entries, source = _read_table(folder / BUDGET_FILE)
    measured = source.get("model")  # absent from tables made before the bench named its model
    if isinstance(measured, dict):
        present = model_identity(folder)
        if any(measured.get(key) != present[key] for key in ("version", "weights")):
            raise BudgetError(
                f"{folder / BUDGET_FILE} was measured with another model (version "
                f"{measured.get('version')}, weights {measured.get('weights')}), not this one "
                f"(version {present['version']}, weights {present['weights']}): bench it again "
                f"('usd-garment bench ... -o DIR') and copy DIR/{BUDGET_FILE} into {folder}"
            )
    return pick(entries, error_mm)
