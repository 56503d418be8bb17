"""Figures of a garment template against its rest body: size, openings, clearance, triangle
evenness and mesh soundness."""

from __future__ import annotations

from typing import Any

import numpy as np

from usd_garment.body.model import BodyModel
from usd_garment.garment.hull import points_inside
from usd_garment.garment.mesh_ops import (
    boundary_loops,
    edge_face_counts,
    face_components,
    face_edges,
    vertex_normals,
)
from usd_garment.garment.template import GarmentTemplate
from usd_garment.garment.templates import recipe, rest_body


def clearance(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance ``(N,)`` (m) of ``points`` ``(N, 3)`` to a closed mesh (negative inside)
    and the closest surface points ``(N, 3)``.

    The sign comes from ray crossing counts (``points_inside``), exact for a watertight mesh.
    """
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    closest, distance, _ = trimesh.proximity.closest_point(mesh, points)
    return np.where(points_inside(vertices, faces, points), -distance, distance), closest


def garment_summary(template: GarmentTemplate, body: BodyModel) -> dict[str, Any]:
    """Counts, openings, clearance to the rest body (m), edge lengths and manifold facts.

    Each boundary loop is matched to the recipe opening whose plane it lies closest to (largest
    distance of its vertices to the plane, m).
    """
    v = template.vertices.astype(np.float64)
    f = template.faces.astype(np.int64)
    body_v, body_f, joints, _ = rest_body(body)
    planes = recipe(template.name, joints).planes
    loops = []
    for loop in boundary_loops(f):
        off = [float(np.abs((v[loop] - p.point) @ p.normal).max()) for p in planes]
        best = int(np.argmin(off))
        loops.append(
            {"opening": planes[best].name, "vertices": len(loop), "plane_distance_m": off[best]}
        )
    sd, closest = clearance(v, body_v, body_f)
    edges, counts = edge_face_counts(f)
    length = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    directed = face_edges(f)
    outward = (vertex_normals(v, f) * (v - closest)).sum(1) > 0
    return {
        "name": template.name,
        "lod": template.lod,
        "body": template.body,
        "vertices": len(v),
        "faces": len(f),
        "boundary_loops": len(loops),
        "loops": loops,
        "clearance_min_m": round(float(sd.min()), 5),
        "clearance_median_m": round(float(np.median(sd)), 5),
        "vertices_inside_body": int((sd < 0).sum()),
        "edge_length_mean_m": round(float(length.mean()), 5),
        "edge_length_cv": round(float(length.std() / length.mean()), 4),
        "max_faces_per_edge": int(counts.max()),
        "boundary_edges": int((counts == 1).sum()),
        "components": len(np.unique(face_components(f, len(v)))),
        "consistent_orientation": len(np.unique(directed, axis=0)) == len(directed),
        "outward_normals_share": round(float(outward.mean()), 4),
        "euler_characteristic": len(v) - len(edges) + len(f),
        "uv_range": [float(template.uvs.min()), float(template.uvs.max())],
    }
