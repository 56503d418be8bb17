"""Read a garment layer written by :mod:`usd_garment.usd.garment_layer` back into numpy, in the
canonical frame (Y-up, metres), value clips included: for evaluation and round trips."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

from usd_garment.usd.errors import UsdInputError
from usd_garment.usd.garment_layer import CANONICAL_TO_LOCAL_KEY, LOD_VARIANT_SET


@dataclass
class GarmentLayerInfo:
    """What else a garment layer says about one garment.

    Attributes:
        path: the layer file.
        mesh: prim path of the garment mesh.
        time_codes: ``(T,)`` time codes of the samples.
        time_codes_per_second: the layer's timeCodesPerSecond.
        method: ``garment:method``; empty if not authored.
        canonical_to_local: ``(4, 4)`` row-vector matrix, canonical frame → mesh local space.
        flagged: ``(T,)`` bool, the frames a simulation kept although they failed its checks
            (``per_frame.bad`` of ``garment:solverSettings``); all False where the layer records
            no per-frame quality (another method).
    """

    path: Path
    mesh: str
    time_codes: np.ndarray
    time_codes_per_second: float
    method: str
    canonical_to_local: np.ndarray
    flagged: np.ndarray


def garment_meshes(stage: Usd.Stage) -> list[Usd.Prim]:
    """The garment meshes of a stage (meshes carrying our canonical-frame record; proxy-purpose
    meshes, the decimated stand-ins of a garment, are not garments of their own)."""
    return [
        prim
        for prim in stage.Traverse(Usd.PrimAllPrimsPredicate)
        if prim.IsA(UsdGeom.Mesh)
        and CANONICAL_TO_LOCAL_KEY in prim.GetCustomData()
        and UsdGeom.Imageable(prim).GetPurposeAttr().Get() != UsdGeom.Tokens.proxy
    ]


def read_garment_layer(
    path: str | Path, garment: str | None = None, lod: str | None = None
) -> tuple[np.ndarray, np.ndarray, GarmentLayerInfo]:
    """Points ``(T, N, 3)`` (canonical frame, m, float64), faces ``(F, 3)`` and a description of
    one garment of the layer (``garment``: the mesh name; None if the layer has one garment),
    of its ``lod`` variant ``lod`` (``dress --lod-variants``; None: the selected one; the file
    is not changed).

    Raises:
        UsdInputError: not a readable layer, no such garment or variant, no time samples, or a
            per-frame quality record of another length than the samples.
    """
    _, prim, info = _open_garment(path, garment, lod)  # the stage kept open while the prim is read
    mesh = UsdGeom.Mesh(prim)
    attr = mesh.GetPointsAttr()
    matrix = info.canonical_to_local
    local = np.stack([np.asarray(attr.Get(t), dtype=np.float64) for t in info.time_codes.tolist()])
    points = (local - matrix[3, :3]) @ np.linalg.inv(matrix[:3, :3])
    faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64).reshape(-1, 3)
    if np.linalg.det(matrix[:3, :3]) < 0:
        faces = faces[:, ::-1].copy()
    return points, faces, info


def read_garment_info(path: str | Path, garment: str | None = None) -> GarmentLayerInfo:
    """The description of one garment of the layer without its points (which
    :func:`read_garment_layer` reads too): time codes, method, frame, flagged frames.

    Raises:
        UsdInputError: as :func:`read_garment_layer`.
    """
    return _open_garment(path, garment)[2]


def _open_garment(
    path: str | Path, garment: str | None, lod: str | None = None
) -> tuple[Usd.Stage, Usd.Prim, GarmentLayerInfo]:
    """The opened stage, the garment mesh prim in it (valid while the stage is) and its
    description (see :func:`read_garment_layer`).

    Raises:
        UsdInputError: as :func:`read_garment_layer`.
    """
    path = Path(path)
    if not path.is_file():
        raise UsdInputError(f"{path}: no such file")
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as exc:  # pxr raises Tf.ErrorException, a plain Exception subclass
        raise UsdInputError(f"{path}: cannot open as USD ({exc})") from exc
    if stage is None:
        raise UsdInputError(f"{path}: cannot open as USD")
    meshes = garment_meshes(stage)
    if garment is not None:
        meshes = [m for m in meshes if m.GetName() == garment]
    if len(meshes) != 1:
        names = ", ".join(m.GetName() for m in garment_meshes(stage)) or "none"
        raise UsdInputError(f"{path}: name one garment mesh (found: {names})")
    prim = meshes[0]
    if lod is not None:
        _select_lod(stage, prim, lod, path)
    matrix = np.array(prim.GetCustomData()[CANONICAL_TO_LOCAL_KEY], dtype=np.float64)
    times = np.array(UsdGeom.Mesh(prim).GetPointsAttr().GetTimeSamples(), dtype=np.float64)
    if times.size == 0:
        raise UsdInputError(f"{path}: {prim.GetPath()} has no time-sampled points")
    method_attr = prim.GetAttribute("garment:method")
    method = str(method_attr.Get()) if method_attr and method_attr.HasAuthoredValue() else ""
    info = GarmentLayerInfo(
        path, str(prim.GetPath()), times, stage.GetTimeCodesPerSecond(), method, matrix,
        _flagged_frames(prim, len(times), path),
    )  # fmt: skip
    return stage, prim, info


def _select_lod(stage: Usd.Stage, prim: Usd.Prim, lod: str, path: Path) -> None:
    """Select the ``lod`` variant ``lod`` of ``prim`` in the stage's session layer (the file's
    layers are not edited).

    Raises:
        UsdInputError: the prim has no such variant.
    """
    sets = prim.GetVariantSets()
    names = sets.GetVariantSet(LOD_VARIANT_SET).GetVariantNames() if sets.HasVariantSet(
        LOD_VARIANT_SET) else []  # fmt: skip
    if lod not in names:
        raise UsdInputError(
            f"{path}: {prim.GetPath()} has no '{LOD_VARIANT_SET}' variant '{lod}' "
            f"(variants: {', '.join(names) or 'none'}; dress --lod-variants writes them)"
        )
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        sets.GetVariantSet(LOD_VARIANT_SET).SetVariantSelection(lod)


def _flagged_frames(prim: Usd.Prim, frames: int, path: Path) -> np.ndarray:
    """``(frames,)`` bool: ``per_frame.bad`` of the mesh's ``garment:solverSettings`` (JSON), all
    False when it records none.

    Raises:
        UsdInputError: the record has another length than ``frames``.
    """
    attr = prim.GetAttribute("garment:solverSettings")
    text = str(attr.Get()) if attr and attr.HasAuthoredValue() else ""
    try:
        bad = json.loads(text).get("per_frame", {}).get("bad")
    except (ValueError, AttributeError):  # not JSON, or JSON that is not an object
        bad = None
    if bad is None:
        return np.zeros(frames, dtype=bool)
    if len(bad) != frames:
        raise UsdInputError(
            f"{path}: {prim.GetPath()} records the quality of {len(bad)} frames for {frames} "
            "time samples"
        )
    return np.asarray(bad, dtype=bool)
