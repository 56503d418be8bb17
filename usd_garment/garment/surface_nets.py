"""Naive surface nets: a closed, consistently oriented triangle mesh from a sampled scalar field.

One vertex per grid cell that the zero level crosses (the mean of its edge crossings), one quad
per grid edge with a sign change, split into two triangles along the shorter diagonal.
"""

from __future__ import annotations

import numpy as np

#: The 8 corners of a cell as offsets, and its 12 edges as corner-index pairs.
_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
_EDGES = [
    (a, b)
    for a in range(8)
    for b in range(a + 1, 8)
    if np.abs(_CORNERS[a] - _CORNERS[b]).sum() == 1
]


def surface_nets(
    field: np.ndarray, origin: np.ndarray, spacing: float
) -> tuple[np.ndarray, np.ndarray]:
    """Extract the zero level set of ``field`` (negative inside).

    Args:
        field: ``(nx, ny, nz)`` samples at ``origin + spacing * (i, j, k)``; should be positive
            on the grid's border so that the result is closed.
        origin: ``(3,)`` position of sample ``(0, 0, 0)`` (m).
        spacing: grid step (m).

    Returns:
        vertices ``(N, 3)`` float64 (m) and faces ``(F, 3)`` int64, counter-clockwise seen from
        the positive side (normals point towards increasing ``field``).
    """
    f = np.asarray(field, dtype=np.float64)
    nx, ny, nz = f.shape
    inside = f < 0
    count = sum(
        inside[i : nx - 1 + i, j : ny - 1 + j, k : nz - 1 + k].astype(np.int8)
        for i, j, k in _CORNERS
    )
    active = (count > 0) & (count < 8)
    cells = np.argwhere(active)
    cell_id = np.full(active.shape, -1, dtype=np.int64)
    cell_id[active] = np.arange(len(cells))
    total = np.zeros((len(cells), 3))
    hits = np.zeros(len(cells))
    for a, b in _EDGES:
        pa, pb = cells + _CORNERS[a], cells + _CORNERS[b]
        fa = f[pa[:, 0], pa[:, 1], pa[:, 2]]
        fb = f[pb[:, 0], pb[:, 1], pb[:, 2]]
        cross = (fa < 0) != (fb < 0)
        t = np.where(cross, fa / np.where(cross, fa - fb, 1.0), 0.0)
        total += cross[:, None] * (pa + t[:, None] * (pb - pa))
        hits += cross
    vertices = np.asarray(origin, dtype=np.float64) + spacing * total / hits[:, None]

    quads = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        # grid edges along `axis` from p to p + e_axis, away from the border in u and v
        lo = [0, 0, 0]
        hi = list(f.shape)
        hi[axis] -= 1
        lo[u], lo[v] = 1, 1
        hi[u] -= 1
        hi[v] -= 1
        start = inside[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        step = [0, 0, 0]
        step[axis] = 1
        end = inside[
            lo[0] + step[0] : hi[0] + step[0],
            lo[1] + step[1] : hi[1] + step[1],
            lo[2] + step[2] : hi[2] + step[2],
        ]
        sel = start != end
        p = np.argwhere(sel) + np.array(lo)
        outward = start[sel]  # inside -> outside along +axis: the normal is +axis
        ring = []
        for du, dv in ((-1, -1), (0, -1), (0, 0), (-1, 0)):
            c = p.copy()
            c[:, u] += du
            c[:, v] += dv
            ring.append(cell_id[c[:, 0], c[:, 1], c[:, 2]])
        q = np.stack(ring, axis=1)
        q[~outward] = q[~outward][:, ::-1]
        quads.append(q)
    q = np.concatenate(quads)
    d02 = np.linalg.norm(vertices[q[:, 0]] - vertices[q[:, 2]], axis=1)
    d13 = np.linalg.norm(vertices[q[:, 1]] - vertices[q[:, 3]], axis=1)
    split02 = d02 <= d13
    tri_a = np.where(split02[:, None], q[:, [0, 1, 2]], q[:, [0, 1, 3]])
    tri_b = np.where(split02[:, None], q[:, [0, 2, 3]], q[:, [1, 2, 3]])
    return vertices, np.concatenate([tri_a, tri_b])
