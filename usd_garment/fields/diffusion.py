"""Diffusion targets of the paper's Section 3.1: surface values (skinning weights, shape and pose
blendshape matrices) averaged over the closest surface points of Gaussian samples around a point,
and the exact signed distance to the body mesh.

Closest-point queries run on Warp's BVH (the ``[train]`` extra; imported only when fitting).
Shapes: M points, N samples per point, V body vertices, F faces, C value channels; metres.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse

#: Largest distance (m) the closest-point query searches; fields are fitted well within it.
MAX_QUERY_DISTANCE = 10.0
#: Closest-point queries per Warp launch (bounds the memory of one batch).
QUERIES_PER_BATCH = 2_000_000


def _kernels():  # Warp kernels, built on first use
    import warp as wp

    @wp.kernel
    def closest_kernel(
        mesh: wp.uint64,
        points: wp.array(dtype=wp.vec3),
        max_distance: float,
        face: wp.array(dtype=wp.int32),
        uv: wp.array(dtype=wp.vec2),
    ):
        tid = wp.tid()
        query = wp.mesh_query_point_no_sign(mesh, points[tid], max_distance)
        face[tid] = query.face
        uv[tid] = wp.vec2(query.u, query.v)

    @wp.kernel
    def signed_kernel(
        mesh: wp.uint64,
        points: wp.array(dtype=wp.vec3),
        max_distance: float,
        distance: wp.array(dtype=float),
    ):
        tid = wp.tid()
        p = points[tid]
        query = wp.mesh_query_point_sign_winding_number(mesh, p, max_distance, 2.0, 0.5)
        closest = wp.mesh_eval_position(mesh, query.face, query.u, query.v)
        distance[tid] = query.sign * wp.length(p - closest)

    return wp, closest_kernel, signed_kernel


class BodySurfaceQuery:
    """Closest-point and signed-distance queries on one rest body mesh.

    Args:
        vertices: ``(V, 3)`` rest vertices (m).
        faces: ``(F, 3)`` triangles, counter-clockwise seen from outside; the mesh should be
            closed for the sign of :meth:`signed_distance` to be meaningful.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        wp, self._closest_kernel, self._signed_kernel = _kernels()
        self._wp = wp
        self.vertices = np.asarray(vertices, dtype=np.float32)
        self.faces = np.asarray(faces, dtype=np.int64)
        self._mesh = wp.Mesh(
            points=wp.array(self.vertices, dtype=wp.vec3, device="cpu"),
            indices=wp.array(self.faces.astype(np.int32).reshape(-1), dtype=wp.int32, device="cpu"),
        )

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface points of ``points`` ``(M, 3)``: face ``(M,)`` int64 and barycentric
        coordinates ``(M, 3)`` of that face's three vertices."""
        wp = self._wp
        faces = np.empty(len(points), dtype=np.int64)
        bary = np.empty((len(points), 3), dtype=np.float32)
        for start in range(0, len(points), QUERIES_PER_BATCH):
            chunk = np.ascontiguousarray(points[start : start + QUERIES_PER_BATCH], np.float32)
            pts = wp.array(chunk, dtype=wp.vec3, device="cpu")
            face = wp.empty(len(chunk), dtype=wp.int32, device="cpu")
            uv = wp.empty(len(chunk), dtype=wp.vec2, device="cpu")
            wp.launch(
                self._closest_kernel,
                dim=len(chunk),
                inputs=[self._mesh.id, pts, MAX_QUERY_DISTANCE],
                outputs=[face, uv],
                device="cpu",
            )
            u, v = uv.numpy().T
            faces[start : start + len(chunk)] = face.numpy()
            bary[start : start + len(chunk)] = np.stack([u, v, 1.0 - u - v], axis=1)
        return faces, bary

    def closest_points(self, points: np.ndarray) -> np.ndarray:
        """``(M, 3)`` closest surface points of ``points`` ``(M, 3)``."""
        face, bary = self.closest(points)
        return np.einsum("mk,mkc->mc", bary, self.vertices[self.faces[face]])

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Exact signed distance ``(M,)`` (m) of ``points`` ``(M, 3)``, negative inside; the sign
        comes from the generalised winding number."""
        wp = self._wp
        out = np.empty(len(points), dtype=np.float32)
        for start in range(0, len(points), QUERIES_PER_BATCH):
            chunk = np.ascontiguousarray(points[start : start + QUERIES_PER_BATCH], np.float32)
            pts = wp.array(chunk, dtype=wp.vec3, device="cpu")
            dist = wp.empty(len(chunk), dtype=float, device="cpu")
            wp.launch(
                self._signed_kernel,
                dim=len(chunk),
                inputs=[self._mesh.id, pts, MAX_QUERY_DISTANCE],
                outputs=[dist],
                device="cpu",
            )
            out[start : start + len(chunk)] = dist.numpy()
        return out

    def interpolation_matrix(self, points: np.ndarray) -> scipy.sparse.csr_matrix:
        """Sparse ``(M, V)`` matrix whose row m, applied to per-vertex values, gives the
        barycentric interpolation of those values at the closest surface point of point m."""
        face, bary = self.closest(points)
        rows = np.repeat(np.arange(len(points)), 3)
        shape = (len(points), len(self.vertices))
        return scipy.sparse.csr_matrix(
            (bary.reshape(-1), (rows, self.faces[face].reshape(-1))), shape=shape
        )

    def diffusion_matrix(
        self, points: np.ndarray, samples: int, rng: np.random.Generator
    ) -> scipy.sparse.csr_matrix:
        """Sparse ``(M, V)`` matrix of the paper's diffusion operator: row m averages the
        barycentric interpolation at the closest surface points φ(q_n) of ``samples`` points
        q_n ~ N(p_m, d_m² I), d_m the distance of p_m to the surface (d is the standard
        deviation)."""
        d = np.linalg.norm(points - self.closest_points(points), axis=1)  # (M,)
        q = points[:, None, :] + d[:, None, None] * rng.standard_normal((len(points), samples, 3))
        interp = self.interpolation_matrix(q.reshape(-1, 3).astype(np.float32))
        rows = np.repeat(np.arange(len(points)), samples)
        average = scipy.sparse.csr_matrix(
            (np.full(len(rows), 1.0 / samples), (rows, np.arange(len(rows)))),
            shape=(len(points), len(rows)),
        )
        return (average @ interp).tocsr()

    def diffuse(
        self,
        points: np.ndarray,
        values: np.ndarray,
        samples: int,
        rng: np.random.Generator,
        progress: Callable[[int], None] | None = None,
        chunk: int = 4096,
    ) -> np.ndarray:
        """The diffused field ``(M, C)`` float32 of per-vertex ``values`` ``(V, C)`` at
        ``points`` ``(M, 3)``: :meth:`diffusion_matrix` applied chunk by chunk (so the operator
        of many points is never held at once). ``progress`` receives the number of points done
        after each chunk."""
        out = np.empty((len(points), values.shape[1]), dtype=np.float32)
        for start in range(0, len(points), chunk):
            p = points[start : start + chunk]
            out[start : start + len(p)] = self.diffusion_matrix(p, samples, rng) @ values
            if progress is not None:
                progress(len(p))
        return out
