"""Evaluate a garment layer against the animated body it was made for (and optionally a
reference layer): reads both from USD, poses the body, and computes :mod:`metrics`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.eval.metrics import GarmentMetrics, evaluate_garment
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


def evaluate_layer(
    garment_layer: str | Path,
    body_input: str | Path,
    reference: str | Path | None = None,
    garment: str | None = None,
    body_model: str | Path | None = None,
    skeleton: str | None = None,
) -> tuple[GarmentMetrics, np.ndarray]:
    """Metrics of the garment of ``garment_layer`` on the body of ``body_input``.

    Returns:
        The metrics and the ``(T,)`` time codes they refer to.

    Raises:
        UsdInputError, BodyModelError, ValueError: unreadable or mismatched inputs.
    """
    points, _, info = read_garment_layer(garment_layer, garment)
    body = load_body_model(body_model)
    motion, _ = read_smpl_motion(body_input, body, skeleton)
    idx = _frame_index(motion.time_codes, info.time_codes, str(body_input))
    vertices = posed_body_vertices(body, motion)[idx]
    ref = None
    if reference is not None:
        ref_points, _, ref_info = read_garment_layer(reference, garment)
        if ref_points.shape[1] != points.shape[1]:
            raise UsdInputError(
                f"{reference}: {ref_points.shape[1]} vertices, the garment has {points.shape[1]}"
            )
        ref = ref_points[_frame_index(ref_info.time_codes, info.time_codes, str(reference))]
    step = float(np.median(np.diff(info.time_codes))) if len(info.time_codes) > 1 else 1.0
    fps = info.time_codes_per_second / step
    return evaluate_garment(points, vertices, body.faces.numpy(), fps, ref), info.time_codes
