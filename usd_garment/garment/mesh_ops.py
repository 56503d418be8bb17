"""Triangle-mesh topology and clean-up for garment templates: edges, components, boundary loops,
cutting by planes and tangential relaxation."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components


def face_edges(faces: np.ndarray) -> np.ndarray:
    """``(3F, 2)`` the directed edges of each triangle of ``faces`` ``(F, 3)``, face by face:
    (a, b), (b, c), (c, a)."""
    return faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)


def edge_face_counts(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges ``(E, 2)`` (sorted pairs) and how many faces use each ``(E,)``."""
    e = np.sort(face_edges(faces), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    return edges, counts


def face_components(faces: np.ndarray, num_vertices: int) -> np.ndarray:
    """Label ``(F,)`` of the vertex-connected component each face belongs to."""
    e = faces[:, [0, 1, 1, 2]].reshape(-1, 2)
    graph = sparse.coo_matrix(
        (np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(num_vertices, num_vertices)
    )
    _, labels = connected_components(graph, directed=False)
    return labels[faces[:, 0]]


def is_manifold(faces: np.ndarray) -> bool:
    """Whether every edge has one or two faces and the faces around every vertex form one fan
    (no two sheets touching at a vertex)."""
    _, counts = edge_face_counts(faces)
    if counts.max() > 2:
        return False
    n_faces = len(faces)
    corner = np.arange(3 * n_faces).reshape(n_faces, 3)
    # every face edge (a, b) with its two corners; matching undirected edges join the corners
    a = faces[:, [0, 1, 2]].ravel()
    b = faces[:, [1, 2, 0]].ravel()
    ca = corner[:, [0, 1, 2]].ravel()
    cb = corner[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * (faces.max() + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    same = key[order][1:] == key[order][:-1]
    i, j = order[:-1][same], order[1:][same]
    # corners at the same vertex on either side of the shared edge
    ci = np.stack([ca[i], cb[i]], 1)
    same_way = (a[j] == a[i])[:, None]
    cj = np.where(same_way, np.stack([ca[j], cb[j]], 1), np.stack([cb[j], ca[j]], 1))
    graph = sparse.coo_matrix(
        (np.ones(2 * len(i)), (ci.ravel(), cj.ravel())), shape=(3 * n_faces, 3 * n_faces)
    )
    n_fans, _ = connected_components(graph, directed=False)
    return n_fans == len(np.unique(faces))


def compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop vertices no face uses; returns the new vertices ``(N', 3)`` and faces ``(F, 3)``."""
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]


def largest_component(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep only the component with the most faces."""
    labels = face_components(faces, len(vertices))
    keep = labels == np.bincount(labels).argmax()
    return compact(vertices, faces[keep])


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops as vertex-index arrays, each ordered along the loop.

    Boundary edges are the directed face edges whose reverse no face has; the loops follow the
    faces' orientation.

    Raises:
        ValueError: a vertex starts more than one boundary edge (the boundary is not manifold).
    """
    directed = face_edges(faces)
    key = directed[:, 0] * (faces.max() + 1) + directed[:, 1]
    rkey = directed[:, 1] * (faces.max() + 1) + directed[:, 0]
    boundary = directed[~np.isin(key, rkey)]
    if len(np.unique(boundary[:, 0])) != len(boundary):
        raise ValueError("non-manifold boundary: a vertex starts two boundary edges")
    nxt = dict(zip(boundary[:, 0].tolist(), boundary[:, 1].tolist(), strict=True))
    loops = []
    while nxt:
        start, cur = next(iter(nxt.items()))
        loop = [start]
        del nxt[start]
        while cur != start:
            loop.append(cur)
            cur = nxt.pop(cur)
        loops.append(np.array(loop))
    return loops


def fix_boundary(faces: np.ndarray) -> np.ndarray:
    """Remove faces until the boundary is a set of simple loops.

    Drops, repeatedly, faces with two or three boundary edges (spikes) and the faces around
    vertices that start more than one boundary edge (bow ties). Returns the kept faces.
    """
    while True:
        flat = face_edges(faces)
        n = faces.max() + 1
        key = flat[:, 0] * n + flat[:, 1]
        is_b = ~np.isin(key, flat[:, 1] * n + flat[:, 0])
        spikes = is_b.reshape(-1, 3).sum(1) >= 2
        starts = np.bincount(flat[is_b, 0], minlength=n)
        bowtie = (starts > 1)[faces].any(1)
        drop = spikes | bowtie
        if not drop.any():
            return faces
        faces = faces[~drop]


def cut(
    vertices: np.ndarray, faces: np.ndarray, planes: list[tuple[np.ndarray, np.ndarray]]
) -> tuple[np.ndarray, np.ndarray]:
    """Remove the faces whose centroid lies on the positive side of any plane, keep the largest
    component and make its boundary simple loops.

    Args:
        planes: ``(point (3,), unit normal (3,))`` pairs (m); the normal points at what goes.
    """
    centroid = vertices[faces].mean(1)
    drop = np.zeros(len(faces), dtype=bool)
    for point, normal in planes:
        drop |= (centroid - point) @ normal > 0
    v, f = largest_component(vertices, faces[~drop])
    v, f = largest_component(v, fix_boundary(f))
    return v, f


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals ``(N, 3)``."""
    fn = np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]]
    )
    n = np.zeros_like(vertices)
    for i in range(3):
        np.add.at(n, faces[:, i], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def relax(
    vertices: np.ndarray,
    faces: np.ndarray,
    project: Callable[[np.ndarray], np.ndarray],
    project_boundary: Callable[[np.ndarray], np.ndarray],
    iterations: int = 20,
    step: float = 0.5,
) -> np.ndarray:
    """Even out triangles: area-weighted tangential smoothing, then re-projection.

    Each vertex moves towards the mean of its neighbours weighted by their areas (a third of the
    adjacent faces' area), which shrinks large cells and grows small ones, so triangle sizes
    equalise. Interior vertices move within their tangent plane and are projected with
    ``project``; boundary vertices use their two loop neighbours and ``project_boundary``. Both
    take and return ``(M, 3)`` positions.

    Returns:
        the relaxed vertices ``(N, 3)`` (m).
    """
    v = np.array(vertices, dtype=np.float64)
    n = len(v)
    e = face_edges(faces)
    adj = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(np.float64)
    loops = boundary_loops(faces)
    on_boundary = np.zeros(n, dtype=bool)
    ring_prev = np.arange(n)
    ring_next = np.arange(n)
    for loop in loops:
        on_boundary[loop] = True
        ring_prev[loop] = np.roll(loop, 1)
        ring_next[loop] = np.roll(loop, -1)
    inner = ~on_boundary
    for _ in range(iterations):
        cross = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
        area = np.bincount(faces.ravel(), np.repeat(np.linalg.norm(cross, axis=1), 3), n)
        lap = adj @ (area[:, None] * v) / (adj @ area)[:, None] - v
        nrm = vertex_normals(v, faces)
        lap -= (lap * nrm).sum(1, keepdims=True) * nrm
        a_prev, a_next = area[ring_prev, None], area[ring_next, None]
        blap = (a_prev * v[ring_prev] + a_next * v[ring_next]) / (a_prev + a_next) - v
        v[inner] = project(v[inner] + step * lap[inner])
        v[on_boundary] = project_boundary(v[on_boundary] + step * blap[on_boundary])
    return v
