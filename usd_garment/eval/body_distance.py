"""Signed distance of points to a posed body mesh, per frame: the collision query that the
metrics, the push-out post-process and the simulator's frame checks share.

Inside means a generalized winding number above 0.5 against the posed body (libigl's fast
winding number), which stays right where the body intersects itself (an arm pressed into the
trunk) and across small holes; the sign of the nearest feature's pseudo-normal does not.
An inside point is *forced* when its closest body point lies itself inside the body (probed
just outside that surface): the animation pushes a limb into the trunk there and no garment can
be outside; the rest is *elsewhere*, the garment method's fault. The closest point is searched
among the triangles with the nearest centroids (a k-d tree per frame); its angle-weighted
pseudo-normal (Bærentzen & Aanæs 2005) gives the push-out direction.
Shapes: T frames, N query points, V body vertices, F body faces. Units: metres.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from scipy.spatial import cKDTree

if TYPE_CHECKING:
    import igl

#: Body triangles (nearest by centroid) searched for each point's closest point.
NEAREST_FACES = 12
#: Point-triangle pairs evaluated at once (bounds the memory of one chunk).
PAIRS_PER_CHUNK = 1_000_000
#: A point is inside the body where its generalized winding number exceeds this.
WINDING_INSIDE = 0.5
#: Frames a :class:`BodyPool` worker queries at once.
POOL_FRAMES = 16
#: How far outside its own surface a closest point is probed to tell whether it lies inside
#: another part of the body (m): body parts closer than this count as touching.
FORCED_PROBE = 5e-4


@dataclass
class BodyDistance:
    """Result of :func:`signed_distance`.

    Attributes:
        distance: ``(T, N)`` signed distance (m) to the closest body surface, negative inside
            the body (winding number > 0.5).
        closest: ``(T, N, 3)`` closest point on the body surface (m).
        normal: ``(T, N, 3)`` unit pseudo-normal of the body at the closest point.
        closest_inside: ``(T, N)`` whether the closest point lies inside another part of the
            body; only probed where ``distance`` is below the query's ``probe_below``
            (False elsewhere).
        face: ``(T, N)`` index of the body triangle the closest point lies on.
    """

    distance: np.ndarray
    closest: np.ndarray
    normal: np.ndarray
    closest_inside: np.ndarray
    face: np.ndarray

    def frames(self, a: int, b: int) -> BodyDistance:
        """The result for frames ``a .. b-1``."""
        return BodyDistance(
            self.distance[a:b],
            self.closest[a:b],
            self.normal[a:b],
            self.closest_inside[a:b],
            self.face[a:b],
        )

    @property
    def inside(self) -> np.ndarray:
        """``(T, N)`` bool: inside the body."""
        return self.distance < 0

    @property
    def forced(self) -> np.ndarray:
        """``(T, N)`` bool: inside where a limb is pressed into the body (forced by the pose)."""
        return self.inside & self.closest_inside

    @property
    def elsewhere(self) -> np.ndarray:
        """``(T, N)`` bool: inside the body, not forced (the garment's fault)."""
        return self.inside & ~self.closest_inside


class BodySurface:
    """Topology of a triangle mesh, prepared once for many posed frames.

    Args:
        faces: ``(F, 3)`` triangle indices, counter-clockwise seen from outside.
        num_vertices: V.
    """

    def __init__(self, faces: np.ndarray, num_vertices: int) -> None:
        faces = np.asarray(faces, dtype=np.int64)
        self.faces = torch.from_numpy(faces)
        self.num_vertices = num_vertices
        # Incident faces of every vertex, padded by repeating the vertex's first face.
        corner_vertex = faces.reshape(-1)
        corner_face = np.repeat(np.arange(len(faces)), 3)
        order = np.argsort(corner_vertex, kind="stable")
        counts = np.bincount(corner_vertex, minlength=num_vertices)
        width = max(int(counts.max()), 1)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(len(order)) - np.repeat(starts, counts)
        table = np.full((num_vertices, width), -1, dtype=np.int64)
        table[corner_vertex[order], slot] = corner_face[order]
        first = np.where(table[:, 0] >= 0, table[:, 0], 0)
        table = np.where(table >= 0, table, first[:, None])
        self.vertex_faces = torch.from_numpy(table)  # (V, width)
        # Face across each edge e = (v_e, v_{e+1}); the face itself on a boundary edge.
        edges = np.stack([faces, np.roll(faces, -1, axis=1)], axis=-1).reshape(-1, 2)
        key = np.minimum(edges[:, 0], edges[:, 1]) * num_vertices + np.maximum(
            edges[:, 0], edges[:, 1]
        )
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        across = np.arange(len(key)) // 3
        same_next = np.zeros(len(key), dtype=bool)
        same_next[:-1] = sorted_key[1:] == sorted_key[:-1]
        pair_a, pair_b = order[:-1][same_next[:-1]], order[1:][same_next[:-1]]
        neighbour = across.copy()
        neighbour[pair_a] = across[pair_b]
        neighbour[pair_b] = across[pair_a]
        self.edge_neighbour = torch.from_numpy(neighbour.reshape(-1, 3))  # (F, 3)

    def vertex_normals(
        self, vertices: torch.Tensor, frame: torch.Tensor, index: torch.Tensor
    ) -> torch.Tensor:
        """Angle-weighted unit pseudo-normals ``(M, 3)`` of vertex ``index[m]`` of the mesh
        ``vertices[frame[m]]``; ``vertices`` ``(B, V, 3)``, ``frame`` and ``index`` ``(M,)``."""
        faces = self.vertex_faces[index]  # (M, W); padding repeats a face: count it once
        once = torch.cat([torch.ones_like(faces[:, :1], dtype=torch.bool),
                          faces[:, 1:] != faces[:, :1]], dim=-1)  # fmt: skip
        corners = self.faces[faces]  # (M, W, 3)
        tri = vertices[frame[:, None, None], corners]  # (M, W, 3, 3)
        at = (corners == index[:, None, None]).float()[..., None]  # (M, W, 3, 1)
        p = (tri * at).sum(-2)
        e1 = torch.nn.functional.normalize((torch.roll(tri, -1, dims=-2) * at).sum(-2) - p, dim=-1)
        e2 = torch.nn.functional.normalize((torch.roll(tri, 1, dims=-2) * at).sum(-2) - p, dim=-1)
        angle = torch.arccos((e1 * e2).sum(-1).clamp(-1.0, 1.0)) * once
        return torch.nn.functional.normalize(
            (angle[..., None] * _face_normals(tri)).sum(-2), dim=-1
        )


def _tree(points: np.ndarray) -> cKDTree:
    """A k-d tree built for one query batch (unbalanced: ~2x faster to build)."""
    return cKDTree(points, leafsize=32, balanced_tree=False, compact_nodes=False)


class BodyFrames:
    """The search structures of each frame of a posed body: the k-d tree of the triangles'
    centroids and libigl's winding-number hierarchy (several MB a frame for the default body).
    With ``keep``, each is built on first use and kept for every later query of those frames
    (the push-out's passes over a block of frames); without, built at each use and dropped (one
    query of many frames, whose memory must not grow with their number).

    Args:
        body_vertices: ``(T, V, 3)`` posed body vertices (m).
        surface: the body's topology.
        keep: hold the structures once built.
    """

    def __init__(
        self, body_vertices: np.ndarray | torch.Tensor, surface: BodySurface, keep: bool = True
    ) -> None:
        self.vertices = torch.as_tensor(body_vertices).float()
        self.faces = surface.faces
        self._centroids: dict[int, cKDTree] | None = {} if keep else None
        self._winding: dict[int, igl.FastWindingNumberBVH] | None = {} if keep else None

    def centroid_tree(self, t: int) -> cKDTree:
        """The k-d tree of frame ``t``'s triangle centroids (triangle order of the faces)."""
        if self._centroids is not None and t in self._centroids:
            return self._centroids[t]
        tree = _tree(self.vertices[t][self.faces].mean(dim=1).numpy())  # centroids (F, 3)
        if self._centroids is not None:
            self._centroids[t] = tree
        return tree

    def winding(self, t: int) -> igl.FastWindingNumberBVH:
        """The winding-number hierarchy of frame ``t`` (:func:`winding_tree`)."""
        if self._winding is not None and t in self._winding:
            return self._winding[t]
        tree = winding_tree(self.vertices[t].numpy(), self.faces.numpy())
        if self._winding is not None:
            self._winding[t] = tree
        return tree


def _gather(vertices: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``vertices[b, index[b, ...]]`` for ``vertices`` ``(B, V, 3)``: shape ``(*index, 3)``."""
    frame = torch.arange(vertices.shape[0]).reshape(-1, *([1] * (index.dim() - 1)))
    return vertices[frame, index]


def _face_normals(tri: torch.Tensor) -> torch.Tensor:
    """Unit normals ``(..., 3)`` of triangles ``(..., 3, 3)``."""
    a, b, c = tri.unbind(-2)
    return torch.nn.functional.normalize(torch.cross(b - a, c - a, dim=-1), dim=-1)


def _closest_on_triangles(
    p: torch.Tensor, a: torch.Tensor, b: torch.Tensor, c: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Closest points ``(..., 3)`` on triangles (a, b, c) to points p, and the feature code
    ``(...)``: 0 interior, 1-3 edge ab/bc/ca, 4-6 vertex a/b/c. All inputs ``(..., 3)``."""
    ab, ac = b - a, c - a
    n = torch.cross(ab, ac, dim=-1)
    nn = (n * n).sum(-1).clamp_min(1e-30)
    ap = p - a
    # Barycentrics of the projection onto the plane.
    v = (torch.cross(ap, ac, dim=-1) * n).sum(-1) / nn
    w = (torch.cross(ab, ap, dim=-1) * n).sum(-1) / nn
    u = 1.0 - v - w
    inside = (u >= 0) & (v >= 0) & (w >= 0)
    best = a + v[..., None] * ab + w[..., None] * ac
    best_d = torch.where(inside, ((p - best) ** 2).sum(-1), torch.full_like(u, float("inf")))
    code = torch.zeros_like(u, dtype=torch.int64)
    for k, (s, e) in enumerate(((a, b), (b, c), (c, a))):
        se = e - s
        t = (((p - s) * se).sum(-1) / (se * se).sum(-1).clamp_min(1e-30)).clamp(0.0, 1.0)
        q = s + t[..., None] * se
        d = ((p - q) ** 2).sum(-1)
        better = (~inside) & (d < best_d)
        best = torch.where(better[..., None], q, best)
        best_d = torch.where(better, d, best_d)
        edge_code = torch.where(t <= 0.0, 4 + k, torch.where(t >= 1.0, 4 + (k + 1) % 3, 1 + k))
        code = torch.where(better, edge_code, code)
    return best, code


def winding_tree(vertices: np.ndarray, faces: np.ndarray) -> igl.FastWindingNumberBVH:
    """libigl's fast-winding-number hierarchy of the triangle mesh ``vertices`` ``(V, 3)`` (m),
    ``faces`` ``(F, 3)``, built once for several queries (its build is most of a query's cost;
    about 5 MB for the body). libigl is imported here, at the first tree: the commands that
    test no point against the body (``dress``'s default) do not load it."""
    import igl

    tree = igl.FastWindingNumberBVH()
    tree.init(
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(faces, dtype=np.int64),
    )
    return tree


def tree_winding_numbers(tree: igl.FastWindingNumberBVH, points: np.ndarray) -> np.ndarray:
    """Generalized winding numbers ``(M,)`` of ``points`` ``(M, 3)`` (m) against the mesh of
    ``tree``: ~1 inside, ~0 outside, ~2 where two parts overlap."""
    if len(points) == 0:
        return np.zeros(0)
    return tree.winding_number(np.ascontiguousarray(points, dtype=np.float64))


def winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """:func:`tree_winding_numbers` against the triangle mesh ``vertices`` ``(V, 3)`` (m),
    ``faces`` ``(F, 3)`` (libigl's fast winding number)."""
    if len(points) == 0:
        return np.zeros(0)
    return tree_winding_numbers(winding_tree(vertices, faces), points)


def signed_distance(
    points: np.ndarray | torch.Tensor,
    body_vertices: np.ndarray | torch.Tensor,
    surface: BodySurface,
    nearest: int = NEAREST_FACES,
    probe_below: float = 0.0,
    frames: BodyFrames | None = None,
    pool: BodyPool | None = None,
) -> BodyDistance:
    """Signed distance of ``points`` ``(T, N, 3)`` to the body ``(T, V, 3)``, frame by frame.

    The closest point is searched among the ``nearest`` triangles whose centroids are nearest
    (a k-d tree per frame), in float32; the sign is the winding-number inside test. Where the
    signed distance is below ``probe_below`` (m; 0: the inside points only), the closest point
    is probed ``FORCED_PROBE`` outside its surface for lying inside the body. ``frames``: the
    search structures of ``body_vertices``' frames (:class:`BodyFrames`, whose vertices are
    then used), when the caller queries the same frames again; None: built here at each use.
    ``pool``: worker processes that query blocks of :data:`POOL_FRAMES` frames in parallel
    (the same result; ``frames`` is then not used).
    """
    if pool is not None and len(points) > POOL_FRAMES:
        starts = range(0, len(points), POOL_FRAMES)
        parts = list(pool.map(
            _distance_block, [np.asarray(points[a : a + POOL_FRAMES]) for a in starts],
            [np.asarray(body_vertices[a : a + POOL_FRAMES]) for a in starts],
            [surface.faces.numpy()] * len(starts), [probe_below] * len(starts),
        ))  # fmt: skip
        return BodyDistance(*(np.concatenate(arrays) for arrays in zip(
            *((p.distance, p.closest, p.normal, p.closest_inside, p.face) for p in parts),
            strict=True,
        )))  # fmt: skip
    pts = torch.as_tensor(points).float()
    if frames is None:  # each frame's structures are used once here: not kept
        frames = BodyFrames(body_vertices, surface, keep=False)
    verts = frames.vertices
    t_frames, n = pts.shape[:2]
    k = min(nearest, surface.faces.shape[0])
    chunk = max(1, PAIRS_PER_CHUNK // max(1, n * k))
    dist = np.empty((t_frames, n))
    closest = np.empty((t_frames, n, 3))
    normal = np.empty((t_frames, n, 3))
    closest_face = np.empty((t_frames, n), dtype=np.int64)
    for s in range(0, t_frames, chunk):
        p, v = pts[s : s + chunk], verts[s : s + chunk]
        b = p.shape[0]
        cand = np.stack(
            [frames.centroid_tree(s + i).query(p[i].numpy(), k=k)[1].reshape(n, k)
             for i in range(b)]
        )  # fmt: skip
        cand = torch.from_numpy(cand)  # (b, n, k) face indices
        tri = _gather(v, surface.faces[cand])  # (b, n, k, 3, 3)
        q, code = _closest_on_triangles(p[:, :, None], *tri.unbind(-2))
        best = ((p[:, :, None] - q) ** 2).sum(-1).argmin(-1, keepdim=True)  # (b, n, 1)
        q = torch.gather(q, 2, best[..., None].expand(-1, -1, 1, 3))[:, :, 0]
        code = torch.gather(code, 2, best)[..., 0]
        face = torch.gather(cand, 2, best)[..., 0]  # (b, n)
        n_face = _face_normals(_gather(v, surface.faces[face]))
        edge = (code - 1).clamp(0, 2)
        across = surface.edge_neighbour[face, edge]
        n_edge = torch.nn.functional.normalize(
            n_face + _face_normals(_gather(v, surface.faces[across])), dim=-1
        )
        corner = torch.gather(surface.faces[face], 2, (code - 4).clamp(0, 2)[..., None])[..., 0]
        pseudo = torch.where((code == 0)[..., None], n_face, n_edge)
        at_vertex = (code >= 4).nonzero(as_tuple=True)
        if at_vertex[0].numel():
            pseudo[at_vertex] = surface.vertex_normals(v, at_vertex[0], corner[at_vertex])
        closest[s : s + b] = q.numpy()
        normal[s : s + b] = pseudo.numpy()
        closest_face[s : s + b] = face.numpy()
        dist[s : s + b] = (p - q).norm(dim=-1).numpy()
    closest_inside = np.zeros((t_frames, n), dtype=bool)
    for t in range(t_frames):
        tree = frames.winding(t)
        inside = tree_winding_numbers(tree, pts[t].numpy()) > WINDING_INSIDE
        dist[t] = np.where(inside, -dist[t], dist[t])
        probe = np.flatnonzero(dist[t] < probe_below)
        if probe.size:
            at = closest[t, probe] + FORCED_PROBE * normal[t, probe]
            closest_inside[t, probe] = tree_winding_numbers(tree, at) > WINDING_INSIDE
    return BodyDistance(dist, closest, normal, closest_inside, closest_face)


class BodyPool:
    """Worker processes (one CPU core each: one torch thread; started once, "spawn") that run
    body queries on blocks of frames (``dress --workers``, ``eval --workers``, ``bench
    --workers``); use as a context manager, or :meth:`close` it. A script that makes one needs
    the usual ``if __name__ == "__main__":`` guard (the workers import the main module).

    Args:
        workers: processes.
    """

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._executor = ProcessPoolExecutor(  # one torch thread: one core per worker
            workers, mp_context=multiprocessing.get_context("spawn"),
            initializer=torch.set_num_threads, initargs=(1,),
        )  # fmt: skip

    def map(self, function: Callable[..., Any], *jobs: Iterable[Any]) -> Iterator[Any]:
        """``function(*args)`` for the arguments of each job in the workers (a module-level
        function; a body topology among its arguments goes through :func:`worker_surface`);
        results in order."""
        return self._executor.map(function, *jobs)

    def close(self) -> None:
        """Stop the workers."""
        self._executor.shutdown()

    def __enter__(self) -> BodyPool:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


#: The pools :func:`body_pool` has open, by size, with how many of its contexts use each.
_OPEN_POOLS: dict[int, tuple[BodyPool, int]] = {}


@contextmanager
def body_pool(workers: int) -> Iterator[BodyPool | None]:
    """A :class:`BodyPool` of ``workers`` processes, or None when one process does the work
    (``workers`` ≤ 1), as a context. A context entered while another of the same size is open
    shares its pool, which stops when the last of them exits: ``dress --lod-variants
    --workers N`` dresses each level with the pushing method in turn, one pool for them all."""
    if workers <= 1:
        yield None
        return
    pool, users = _OPEN_POOLS.get(workers, (None, 0))
    if pool is None:
        pool = BodyPool(workers)
    _OPEN_POOLS[workers] = (pool, users + 1)
    try:
        yield pool
    finally:
        pool, users = _OPEN_POOLS.pop(workers)
        if users > 1:
            _OPEN_POOLS[workers] = (pool, users - 1)
        else:
            pool.close()


#: The body topology last used by this worker process (:class:`BodyPool`).
_WORKER_SURFACE: list[BodySurface] = []


def worker_surface(faces: np.ndarray, num_vertices: int) -> BodySurface:
    """The topology of the mesh ``faces`` ``(F, 3)`` with ``num_vertices`` vertices, built once
    per worker process of a :class:`BodyPool` while the jobs keep to one mesh."""
    if not (
        _WORKER_SURFACE
        and _WORKER_SURFACE[0].num_vertices == num_vertices
        and np.array_equal(_WORKER_SURFACE[0].faces.numpy(), faces)
    ):
        _WORKER_SURFACE[:] = [BodySurface(faces, num_vertices)]
    return _WORKER_SURFACE[0]


def _distance_block(
    points: np.ndarray,
    body_vertices: np.ndarray,
    faces: np.ndarray,
    probe_below: float,
) -> BodyDistance:
    """:func:`signed_distance` of one block of frames, in a worker of a :class:`BodyPool`."""
    surface = worker_surface(faces, body_vertices.shape[1])
    return signed_distance(points, body_vertices, surface, probe_below=probe_below)
