"""Inverse linear blend skinning, and the two unposing baselines of the paper's Fig. 5: constant
weights (each garment vertex takes the weights and blendshapes of the rest-body vertex nearest to
its template position, TailorNet / Santesteban-2019 style) and per-frame nearest-vertex weights
(the posed-body vertex nearest to the simulated vertex, searched again every frame).

Shapes: T frames, N garment points, V body vertices, J = 24 joints. Units: metres, radians.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from scipy.spatial import cKDTree

from usd_garment.body.lbs import batch_rodrigues, inverse_skin, pose_features, skin
from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.methods.lbs import nearest_body_vertex

#: Frames unposed at once (bounds memory: the body pass holds ~V·12 floats per frame).
FRAMES_PER_CHUNK = 64


def _body_offsets(
    body: BodyModel, index: torch.Tensor, betas: torch.Tensor, feats: torch.Tensor
) -> torch.Tensor:
    """Shape (and pose) blendshape offsets ``(B, N, 3)`` of body vertices ``index`` ``(B, N)``."""
    offset = torch.einsum("bk,bnck->bnc", betas, body.shapedirs[index])
    if body.has_pose_blendshapes:
        offset = offset + torch.einsum("bp,bncp->bnc", feats, body.posedirs[index])
    return offset


@dataclass
class Unposed:
    """Result of an unposing baseline.

    Attributes:
        canonical: ``(T, N, 3)`` float32 canonical points (m).
        body_vertex: ``(T, N)`` int64 body vertex whose weights and blendshapes each point took.
    """

    canonical: np.ndarray
    body_vertex: np.ndarray


def unpose_constant_weights(
    body: BodyModel,
    template: GarmentTemplate,
    points: np.ndarray,
    betas: np.ndarray,
    pose: np.ndarray,
    trans: np.ndarray,
) -> Unposed:
    """Unpose posed garment ``points`` ``(T, N, 3)`` by inverse LBS with the weights and
    blendshapes of each template vertex's nearest rest-body vertex; ``betas`` ``(10,)`` or
    ``(T, 10)``, ``pose`` ``(T, 24, 3)`` (rad), ``trans`` ``(T, 3)`` (m)."""
    index = torch.from_numpy(nearest_body_vertex(body, template))
    return _unpose(body, points, betas, pose, trans, lambda s, e, posed: index.expand(e - s, -1))


def unpose_nearest_vertex(
    body: BodyModel, points: np.ndarray, betas: np.ndarray, pose: np.ndarray, trans: np.ndarray
) -> Unposed:
    """Unpose by inverse LBS with the weights and blendshapes of the posed-body vertex nearest to
    each garment point, searched anew every frame."""

    def nearest(s: int, e: int, posed: torch.Tensor) -> torch.Tensor:
        return torch.from_numpy(
            np.stack([cKDTree(posed[i].numpy()).query(points[s + i])[1] for i in range(e - s)])
        )

    return _unpose(body, points, betas, pose, trans, nearest)


def _unpose(
    body: BodyModel,
    points: np.ndarray,
    betas: np.ndarray,
    pose: np.ndarray,
    trans: np.ndarray,
    choose: Callable[[int, int, torch.Tensor], torch.Tensor],
) -> np.ndarray:
    """Inverse LBS of ``points`` with the body vertices ``choose(s, e, posed_body_vertices)``
    ``(e − s, N)`` for frames ``s .. e−1``, minus those vertices' blendshape offsets."""
    t_frames = points.shape[0]
    betas_t = torch.as_tensor(np.broadcast_to(betas, (t_frames, betas.shape[-1])).copy()).float()
    pose_t = torch.as_tensor(pose, dtype=torch.float32)
    trans_t = torch.as_tensor(trans, dtype=torch.float32)
    out = np.empty(points.shape, dtype=np.float32)
    chosen = np.empty(points.shape[:2], dtype=np.int64)
    with torch.no_grad():
        for s in range(0, t_frames, FRAMES_PER_CHUNK):
            e = min(s + FRAMES_PER_CHUNK, t_frames)
            posed = body(betas_t[s:e], pose_t[s:e], trans_t[s:e])
            index = choose(s, e, posed.vertices)
            feats = pose_features(batch_rodrigues(pose_t[s:e]))
            target = torch.as_tensor(points[s:e], dtype=torch.float32)
            rest = inverse_skin(target, body.weights[index], posed.transforms)
            out[s:e] = (rest - _body_offsets(body, index, betas_t[s:e], feats)).numpy()
            chosen[s:e] = index.numpy()
    return Unposed(out, chosen)


def skin_body_vertices(
    body: BodyModel,
    canonical: np.ndarray,
    body_vertex: np.ndarray,
    betas: np.ndarray,
    pose: np.ndarray,
    trans: np.ndarray,
) -> np.ndarray:
    """The forward model the baselines invert: canonical points ``(T, N, 3)`` plus the
    blendshape offsets of ``body_vertex`` ``(T, N)``, skinned with its weights; ``(T, N, 3)``."""
    t_frames = canonical.shape[0]
    betas_t = torch.as_tensor(np.broadcast_to(betas, (t_frames, betas.shape[-1])).copy()).float()
    pose_t = torch.as_tensor(pose, dtype=torch.float32)
    index = torch.from_numpy(np.array(body_vertex, dtype=np.int64))
    with torch.no_grad():
        posed = body(betas_t, pose_t, torch.as_tensor(trans, dtype=torch.float32))
        feats = pose_features(batch_rodrigues(pose_t))
        rest = torch.as_tensor(canonical).float() + _body_offsets(body, index, betas_t, feats)
        return skin(rest, body.weights[index], posed.transforms).numpy()
