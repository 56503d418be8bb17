"""Evaluate a garment layer against the animated body it was made for (and optionally a
reference layer): reads both from USD, poses the body, and computes :mod:`metrics`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.eval.body_distance import BodyPool
from usd_garment.eval.metrics import GarmentMetrics, evaluate_garment, face_joints
from usd_garment.garment.lod import carry_to_lod, lod_with_vertices
from usd_garment.garment.template import GARMENT_NAMES
from usd_garment.motion.cuts import motion_cuts, motion_restarts
from usd_garment.motion.jumps import jump_maps, mapped, root_jumps
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.errors import UsdInputError
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion

#: Frames posed at once.
FRAMES_PER_CHUNK = 256


def posed_body_vertices(body: BodyModel, motion: SmplMotion) -> np.ndarray:
    """Posed body vertices ``(T, V, 3)`` float64 (m, canonical frame) of ``motion``."""
    betas = torch.as_tensor(motion.betas, dtype=torch.float32)
    pose = torch.as_tensor(motion.pose, dtype=torch.float32)
    trans = torch.as_tensor(motion.trans, dtype=torch.float32)
    out = np.empty((motion.num_frames, body.num_vertices, 3))
    with torch.no_grad():
        for s in range(0, motion.num_frames, FRAMES_PER_CHUNK):
            e = s + FRAMES_PER_CHUNK
            out[s:e] = body(betas, pose[s:e], trans[s:e]).vertices.numpy()
    return out


def _frame_index(codes: np.ndarray, wanted: np.ndarray, where: str) -> np.ndarray:
    """Indices into ``codes`` of the time codes ``wanted``; every one must be there."""
    idx = np.clip(np.searchsorted(codes, wanted), 0, max(len(codes) - 1, 0))
    if len(codes) == 0 or not np.allclose(codes[idx], wanted):
        raise UsdInputError(f"{where}: the garment's time codes are not all in the body's range")
    return idx


def _same_lod(reference: np.ndarray, vertices: int, garment: str, where: str | Path) -> np.ndarray:
    """``reference`` ``(T, N_ref, 3)`` carried to the level of detail of ``garment`` that has
    ``vertices`` vertices, when both are levels of detail of that committed garment.

    Raises:
        UsdInputError: they are not.
    """
    source, target = (lod_with_vertices(garment, n) if garment in GARMENT_NAMES else None
                      for n in (reference.shape[1], vertices))  # fmt: skip
    if source is None or target is None:
        raise UsdInputError(
            f"{where}: {reference.shape[1]} vertices, the garment has {vertices} (and they are "
            "not two levels of detail of one garment)"
        )
    return carry_to_lod(reference, garment, source, target)


def evaluate_layer(
    garment_layer: str | Path,
    body_input: str | Path,
    reference: str | Path | None = None,
    garment: str | None = None,
    body_model: str | Path | None = None,
    skeleton: str | None = None,
    pool: BodyPool | None = None,
    lod: str | None = None,
) -> tuple[GarmentMetrics, np.ndarray]:
    """Metrics of the garment of ``garment_layer`` (its ``lod`` variant ``lod``; None: the
    selected one) on the body of ``body_input``; against a ``reference`` layer of another
    level of detail of the same garment, the reference is carried to the garment's level of
    detail first (:mod:`usd_garment.garment.lod`); no acceleration is measured across the body's
    restarts (``motion_restarts``: a splice of the joints, one the body layer's ``smpl:cuts``
    declares), and across a jump of its root alone (a teleport, a snapped heading) it is
    measured with the jump taken out (``jump_maps``). ``pool``: worker processes that measure
    blocks of frames (the same figures).

    Returns:
        The metrics and the ``(T,)`` time codes they refer to.

    Raises:
        UsdInputError, BodyModelError, ValueError: unreadable or mismatched inputs.
    """
    points, _, info = read_garment_layer(garment_layer, garment, lod)
    body = load_body_model(body_model)
    motion, _ = read_smpl_motion(body_input, body, skeleton)
    idx = _frame_index(motion.time_codes, info.time_codes, str(body_input))
    vertices = posed_body_vertices(body, motion)[idx]
    ref = None
    if reference is not None:
        ref_points, _, ref_info = read_garment_layer(reference, garment)
        if ref_points.shape[1] != points.shape[1]:
            ref_points = _same_lod(ref_points, points.shape[1], Path(info.mesh).name, reference)
        ref = ref_points[_frame_index(ref_info.time_codes, info.time_codes, str(reference))]
    step = float(np.median(np.diff(info.time_codes))) if len(info.time_codes) > 1 else 1.0
    fps = info.time_codes_per_second / step
    faces = body.faces.numpy()
    parts = face_joints(body.weights.numpy(), faces)
    # The motion's restarts at the garment's frames (the first at or after each); across a jump
    # of the root alone the acceleration is measured with the jump taken out.
    restarts = motion_restarts(motion)
    jumps = root_jumps(motion, body, motion_cuts(motion, restarts), restarts)
    steady = mapped(jump_maps(motion.num_frames, jumps)[idx], points) if jumps else None
    cuts = [j for j in np.searchsorted(idx, restarts).tolist() if 0 < j < len(idx)]
    metrics = evaluate_garment(points, vertices, faces, fps, ref, pool, parts, cuts, steady)
    return metrics, info.time_codes
