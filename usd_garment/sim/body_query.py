"""Signed distance of garment vertices to the simulator's body mesh, queried with Warp on the
collider's own BVH (imported only with the simulator: it needs the ``[train]`` extra)."""

from __future__ import annotations

import numpy as np
import warp as wp

#: Search radius of the closest-point query (m): farther points read this distance.
MAX_DISTANCE = 100.0


@wp.kernel
def _signed_distance_kernel(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    max_distance: float,
    distance: wp.array(dtype=float),
):
    tid = wp.tid()
    p = points[tid]
    query = wp.mesh_query_point_sign_normal(mesh, p, max_distance)
    if query.result:
        closest = wp.mesh_eval_position(mesh, query.face, query.u, query.v)
        distance[tid] = query.sign * wp.length(p - closest)
    else:
        distance[tid] = max_distance


def signed_distance(mesh: wp.Mesh, points: wp.array) -> np.ndarray:
    """Signed distance of ``points`` to ``mesh`` (its current, refitted points).

    The sign comes from the angle-weighted pseudo-normal of the closest feature, exact for a
    closed, consistently wound mesh (faces counter-clockwise seen from outside).

    Args:
        mesh: the body collider's ``wp.Mesh``.
        points: ``(N,)`` ``wp.vec3`` query points (m) on the mesh's device.

    Returns:
        ``(N,)`` float32 distances (m), negative inside.
    """
    out = wp.empty(points.shape[0], dtype=float, device=points.device)
    wp.launch(
        _signed_distance_kernel,
        dim=points.shape[0],
        inputs=[mesh.id, points, MAX_DISTANCE],
        outputs=[out],
        device=points.device,
    )
    return out.numpy()
