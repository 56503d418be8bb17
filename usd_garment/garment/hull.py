"""Voxel hulls of a body: inside/outside on a grid, morphological closing, and an offset field.

The garment surface is the level set ``field = 0`` of the signed distance (m) to a closed body
region minus the ease; a ``FieldSampler`` evaluates that field and projects points onto it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class Grid:
    """A regular grid: sample ``(i, j, k)`` sits at ``origin + spacing * (i, j, k)`` (m)."""

    origin: np.ndarray
    spacing: float
    shape: tuple[int, int, int]

    @classmethod
    def covering(cls, lo: np.ndarray, hi: np.ndarray, spacing: float) -> Grid:
        """The grid with step ``spacing`` (m) whose samples cover the box ``lo..hi`` ``(3,)``."""
        lo = np.asarray(lo, dtype=np.float64)
        n = np.ceil((np.asarray(hi) - lo) / spacing).astype(int) + 1
        return cls(lo, float(spacing), (int(n[0]), int(n[1]), int(n[2])))

    def axis(self, i: int) -> np.ndarray:
        """Sample coordinates ``(shape[i],)`` (m) along axis ``i``."""
        return self.origin[i] + self.spacing * np.arange(self.shape[i])

    def points(self, index: np.ndarray) -> np.ndarray:
        """Positions ``(M, 3)`` (m) of integer samples ``index`` ``(M, 3)``."""
        return self.origin + self.spacing * index


def inside_mesh(vertices: np.ndarray, faces: np.ndarray, grid: Grid) -> np.ndarray:
    """Which grid samples lie inside a closed triangle mesh, ``(nx, ny, nz)`` bool.

    Ray parity along each of the three axes, then a majority vote, so a small hole in the mesh
    only spoils the rays that pass through it along one axis.

    Args:
        vertices: ``(V, 3)`` positions (m); faces: ``(F, 3)`` vertex indices.
    """
    votes = np.zeros(grid.shape, dtype=np.int8)
    for axis in range(3):
        votes += _parity_along(vertices, faces, grid, axis)
    return votes >= 2


def _parity_along(vertices: np.ndarray, faces: np.ndarray, grid: Grid, axis: int) -> np.ndarray:
    """Inside test by counting mesh crossings of rays along ``axis`` (``(nx, ny, nz)`` bool)."""
    u, v = [a for a in range(3) if a != axis]
    tri = vertices[faces]  # (F, 3, 3)
    h = grid.spacing
    # columns of the grid, nudged off lattice-aligned mesh vertices and edges
    cu = (tri[:, :, u] - grid.origin[u]) / h - 1e-7
    cv = (tri[:, :, v] - grid.origin[v]) / h - 2e-7
    iu0 = np.clip(np.ceil(cu.min(1)), 0, grid.shape[u]).astype(np.int64)
    iu1 = np.clip(np.floor(cu.max(1)), -1, grid.shape[u] - 1).astype(np.int64)
    iv0 = np.clip(np.ceil(cv.min(1)), 0, grid.shape[v]).astype(np.int64)
    iv1 = np.clip(np.floor(cv.max(1)), -1, grid.shape[v] - 1).astype(np.int64)
    nu = np.maximum(iu1 - iu0 + 1, 0)
    nv = np.maximum(iv1 - iv0 + 1, 0)
    count = nu * nv
    face = np.repeat(np.arange(len(faces)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    pu = iu0[face] + local // nv[face]
    pv = iv0[face] + local % nv[face]
    # barycentric coordinates of the column in the triangle's projection
    a, b, c = (np.stack([cu[face, i], cv[face, i]], 1) for i in range(3))
    p = np.stack([pu, pv], 1).astype(np.float64)
    e1, e2, ep = b - a, c - a, p - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok = np.abs(det) > 1e-12
    det = np.where(ok, det, 1.0)
    s = (ep[:, 0] * e2[:, 1] - ep[:, 1] * e2[:, 0]) / det
    t = (e1[:, 0] * ep[:, 1] - e1[:, 1] * ep[:, 0]) / det
    hit = ok & (s >= 0) & (t >= 0) & (s + t <= 1)
    w = tri[face[hit], :, axis]
    depth = w[:, 0] + s[hit] * (w[:, 1] - w[:, 0]) + t[hit] * (w[:, 2] - w[:, 0])
    first = np.clip(np.ceil((depth - grid.origin[axis]) / h), 0, grid.shape[axis])
    shape = list(grid.shape)
    shape[axis] += 1
    flips = np.zeros(shape, dtype=np.int32)
    index = [None, None, None]
    index[axis] = first.astype(np.int64)
    index[u], index[v] = pu[hit], pv[hit]
    np.add.at(flips, tuple(index), 1)
    parity = np.cumsum(flips, axis=axis) % 2 == 1
    return np.take(parity, np.arange(grid.shape[axis]), axis=axis)


def points_inside(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Which ``points`` ``(N, 3)`` (m) lie inside a closed triangle mesh, ``(N,)`` bool.

    Counts crossings of rays from each point along +X, +Y and +Z (a majority vote, as in
    ``inside_mesh``); triangles are found through a 2D bucket grid per axis.
    """
    votes = np.zeros(len(points), dtype=np.int8)
    for axis in range(3):
        votes += _ray_parity(vertices, faces, np.asarray(points, dtype=np.float64), axis)
    return votes >= 2


def _ray_parity(
    vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, axis: int
) -> np.ndarray:
    """Odd number of mesh crossings on the ray from each point along +``axis`` ``(N,)`` bool."""
    u, v = [a for a in range(3) if a != axis]
    tri = vertices[faces]
    size = max(float(np.sqrt(np.median(np.ptp(tri[:, :, [u, v]], axis=1).prod(1)))), 1e-6)
    size *= 2.0
    lo = vertices[:, [u, v]].min(0)
    n = np.floor((vertices[:, [u, v]].max(0) - lo) / size).astype(np.int64) + 1
    b0 = np.floor((tri[:, :, [u, v]].min(1) - lo) / size).astype(np.int64)
    b1 = np.floor((tri[:, :, [u, v]].max(1) - lo) / size).astype(np.int64)
    span = b1 - b0 + 1
    count = span[:, 0] * span[:, 1]
    face = np.repeat(np.arange(len(faces)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    bucket = (b0[face, 0] + local // span[face, 1]) * n[1] + b0[face, 1] + local % span[face, 1]
    order = np.argsort(bucket, kind="stable")
    bucket, face = bucket[order], face[order]
    pb = np.floor((points[:, [u, v]] - lo) / size).astype(np.int64)
    valid = ((pb >= 0) & (pb < n)).all(1)
    key = np.where(valid, pb[:, 0] * n[1] + pb[:, 1], -1)
    start = np.searchsorted(bucket, key, side="left")
    stop = np.where(valid, np.searchsorted(bucket, key, side="right"), start)
    per = stop - start
    point = np.repeat(np.arange(len(points)), per)
    cand = face[np.repeat(start, per) + np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)]
    # a ray hits a triangle if its (u, v) lies inside the projection, beyond the point
    a, b, c = (tri[cand, i] for i in range(3))
    q = points[point]
    e1, e2, ep = b - a, c - a, q - a
    det = e1[:, u] * e2[:, v] - e1[:, v] * e2[:, u]
    ok = np.abs(det) > 1e-18
    det = np.where(ok, det, 1.0)
    s = (ep[:, u] * e2[:, v] - ep[:, v] * e2[:, u]) / det
    t = (e1[:, u] * ep[:, v] - e1[:, v] * ep[:, u]) / det
    depth = a[:, axis] + s * e1[:, axis] + t * e2[:, axis]
    hit = ok & (s >= 0) & (t >= 0) & (s + t <= 1) & (depth > q[:, axis])
    return np.bincount(point[hit], minlength=len(points)) % 2 == 1


def signed_distance(solid: np.ndarray, spacing: float) -> np.ndarray:
    """Approximate signed distance (m) to the boundary of a voxel set, negative inside.

    The boundary is taken halfway between inside and outside samples.
    """
    outside = ndimage.distance_transform_edt(~solid) * spacing
    inside = ndimage.distance_transform_edt(solid) * spacing
    return np.where(solid, 0.5 * spacing - inside, outside - 0.5 * spacing)


def closing(solid: np.ndarray, spacing: float, radius: float) -> np.ndarray:
    """Morphological closing of a voxel set by a ball of ``radius`` (m); contains ``solid``."""
    if radius <= 0:
        return solid
    dilated = ndimage.distance_transform_edt(~solid) * spacing <= radius
    return solid | (ndimage.distance_transform_edt(dilated) * spacing > radius)


def offset_field(solid: np.ndarray, spacing: float, ease: float, smooth: float) -> np.ndarray:
    """Field ``(nx, ny, nz)`` float32 whose zero level lies ``ease`` (m) outside ``solid``.

    Args:
        smooth: standard deviation (m) of the Gaussian that removes voxel stair steps.
    """
    field = signed_distance(solid, spacing) - ease
    if smooth > 0:
        field = ndimage.gaussian_filter(field, smooth / spacing)
    return field.astype(np.float32)


class FieldSampler:
    """Trilinear evaluation of a grid field and its gradient; projection onto its zero level."""

    def __init__(self, field: np.ndarray, grid: Grid) -> None:
        self.field = field
        self.grid = grid
        self.gradient = [g / grid.spacing for g in np.gradient(field)]

    def _coords(self, points: np.ndarray) -> np.ndarray:
        return ((points - self.grid.origin) / self.grid.spacing).T

    def value(self, points: np.ndarray) -> np.ndarray:
        """Field values ``(N,)`` at ``points`` ``(N, 3)`` (m); outside the grid: +1."""
        return ndimage.map_coordinates(self.field, self._coords(points), order=1, cval=1.0)

    def grad(self, points: np.ndarray) -> np.ndarray:
        """Field gradients ``(N, 3)`` at ``points`` ``(N, 3)``."""
        c = self._coords(points)
        return np.stack([ndimage.map_coordinates(g, c, order=1) for g in self.gradient], 1)

    def project(self, points: np.ndarray, iterations: int = 4) -> np.ndarray:
        """Move ``points`` ``(N, 3)`` onto the zero level by Newton steps along the gradient."""
        p = np.array(points, dtype=np.float64)
        for _ in range(iterations):
            g = self.grad(p)
            p -= (self.value(p) / np.maximum((g * g).sum(1), 1e-6))[:, None] * g
        return p
