"""Open USD stages with one-line errors, and convert between a stage's world space and our
canonical frame (Y-up, metres, body facing +Z, body's left at +X)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from pxr import Tf, Usd, UsdGeom

from usd_garment.usd.errors import UsdInputError

#: Rotation (row-vector convention, ``v_stage = v_canonical @ R``) from our Y-up canonical
#: axes to a stage's axes: Z-up stages face −Y (a +90° turn about X), as Blender and AMASS do.
UP_AXIS_ROTATIONS: dict[str, np.ndarray] = {
    "Y": np.eye(3),
    "Z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}


def open_stage(path: str | Path) -> Usd.Stage:
    """Open a ``.usd``/``.usda``/``.usdc``/``.usdz`` file with all payloads loaded.

    Raises:
        UsdInputError: the file is missing or USD cannot read it.
    """
    path = Path(path)
    if not path.is_file():
        raise UsdInputError(f"{path}: no such file")
    try:
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise UsdInputError(f"{path}: not a readable USD file ({_first_line(exc)})") from exc
    if stage is None:
        raise UsdInputError(f"{path}: not a readable USD file")
    return stage


def stage_units(stage: Usd.Stage) -> tuple[str, float]:
    """The stage's up axis (``"Y"`` or ``"Z"``) and metres per unit (USD fallbacks when unset)."""
    up_axis = str(UsdGeom.GetStageUpAxis(stage))
    meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(stage))
    if up_axis not in UP_AXIS_ROTATIONS:
        raise UsdInputError(f"upAxis must be Y or Z, got '{up_axis}'")
    if not np.isfinite(meters_per_unit) or meters_per_unit <= 0.0:
        raise UsdInputError(f"metersPerUnit must be positive, got {meters_per_unit}")
    return up_axis, meters_per_unit


def canonical_to_world_matrix(up_axis: str, meters_per_unit: float) -> np.ndarray:
    """``(4, 4)`` float64 row-vector matrix ``p_world = p_canonical @ M`` for a stage's axes and
    units (rotation to the up axis, then metres to stage units)."""
    m = np.eye(4)
    m[:3, :3] = UP_AXIS_ROTATIONS[up_axis] / meters_per_unit
    return m


def _first_line(exc: Exception) -> str:
    """A Tf error's message without its C++ location (``Error in ... : 'msg'``)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    if not lines:
        return type(exc).__name__
    found = re.search(r" : '(.*)'$", lines[0])
    return found.group(1) if found else lines[0]
