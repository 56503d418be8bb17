"""Between levels of detail of a garment: every vertex of one mesh as a barycentric combination of
the closest point on another's rest surface, so that a posed garment at one level of detail can
be carried to another (a simulation at "high" compared with a method at "low", a decimated proxy
of a computed garment)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import sparse

from usd_garment.garment.library import load_template
from usd_garment.garment.template import LODS, GarmentTemplate


def transfer_weights(source: GarmentTemplate, target: GarmentTemplate) -> sparse.csr_matrix:
    """``(N_target, N_source)`` weights, three per row summing to 1: the barycentric coordinates
    of each target vertex's exact closest point on the source's rest surface (libigl, imported
    here: most commands never need it; stop 69: a hundredth of trimesh's time with its import,
    which missed the closest triangle of 2 of the low T-shirt's 1,015 vertices by 0.07 mm)."""
    import igl

    vertices = np.ascontiguousarray(source.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(source.faces, dtype=np.int64)
    points = np.ascontiguousarray(target.vertices, dtype=np.float64)
    _, triangle, closest = igl.point_mesh_squared_distance(points, vertices, faces)
    corners = faces[triangle]  # (N_t, 3)
    a, b, c = (np.ascontiguousarray(vertices[corners[:, k]]) for k in range(3))
    bary = igl.barycentric_coordinates(np.ascontiguousarray(closest), a, b, c)
    bary = np.clip(bary, 0.0, 1.0)
    bary /= bary.sum(axis=1, keepdims=True)
    rows = np.repeat(np.arange(len(target.vertices)), 3)
    shape = (len(target.vertices), len(source.vertices))
    return sparse.csr_matrix((bary.reshape(-1), (rows, corners.reshape(-1))), shape=shape)


@lru_cache(maxsize=16)
def _lod_weights(garment: str, source: str, target: str) -> sparse.csr_matrix:
    return transfer_weights(load_template(garment, source), load_template(garment, target))


def lod_with_vertices(garment: str, vertices: int) -> str | None:
    """The level of detail of the committed ``garment`` template with ``vertices`` vertices."""
    for lod in LODS:
        if len(load_template(garment, lod).vertices) == vertices:
            return lod
    return None


def carry_to_lod(points: np.ndarray, garment: str, source: str, target: str) -> np.ndarray:
    """Garment frames ``(T, N_source, 3)`` (posed, or canonical) of the ``source`` level of
    detail carried to the ``target`` one ``(T, N_target, 3)`` (same units), through the
    rest-surface weights."""
    if source == target:
        return points
    return carry(points, _lod_weights(garment, source, target))


def carry(points: np.ndarray, weights: sparse.csr_matrix) -> np.ndarray:
    """Frames ``(T, N_source, 3)`` carried through :func:`transfer_weights` ``(N_target,
    N_source)`` to ``(T, N_target, 3)``, same dtype, C-contiguous."""
    t, n = points.shape[:2]
    flat = np.asarray(points).transpose(1, 0, 2).reshape(n, t * 3)
    carried = np.asarray(weights @ flat).reshape(-1, t, 3).transpose(1, 0, 2)
    return carried.astype(points.dtype, order="C")
