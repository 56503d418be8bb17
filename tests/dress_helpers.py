"""Stand-ins shared by the dress, garment-layer and eval tests: a tight torso garment cut from the
body itself, and motions (gentle and strong) in our canonical frame."""

from __future__ import annotations

import numpy as np
import trimesh

from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.motion.sequence import SmplMotion


def torso_template(
    body: BodyModel, offset: float = 1.5e-3, name: str = "tshirt"
) -> GarmentTemplate:
    """The rest body's torso surface pushed ``offset`` (m) out along its normals: a tight top."""
    v = body.v_template.numpy().astype(np.float64)
    f = body.faces.numpy()
    normals = trimesh.Trimesh(v, f, process=False).vertex_normals
    keep = (v[:, 1] > -0.3) & (v[:, 1] < 0.3) & (np.abs(v[:, 0]) < 0.25)
    mesh = trimesh.Trimesh(v + offset * normals, f[keep[f].all(axis=1)], process=False)
    mesh.remove_unreferenced_vertices()
    verts = mesh.vertices.astype(np.float32)
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    uvs = ((verts[:, :2] - lo[:2]) / (hi[:2] - lo[:2])).astype(np.float32)
    return GarmentTemplate(name, "high", verts, mesh.faces.astype(np.int32), uvs, body.name)


def strong_motion(frames: int = 12, fps: float = 30.0) -> SmplMotion:
    """Bend forward and sideways, twist, arms down, hips flexed, peaking mid-sequence."""
    w = np.sin(np.linspace(0.0, np.pi, frames)).astype(np.float32)
    pose = np.zeros((frames, 24, 3), dtype=np.float32)
    pose[:, 3, 0], pose[:, 6, 0], pose[:, 9, 0] = 0.6 * w, 0.4 * w, 0.3 * w
    pose[:, 3, 2], pose[:, 6, 1] = 0.4 * w, 0.5 * w
    pose[:, 16, 2], pose[:, 17, 2] = -0.8 * w, 0.8 * w
    pose[:, 1, 0], pose[:, 2, 0] = -0.6 * w, -0.6 * w
    trans = np.zeros((frames, 3), dtype=np.float32)
    trans[:, 2] = np.linspace(0.0, 0.3, frames)
    return SmplMotion(np.zeros(10, np.float32), pose, trans, fps)


def random_motion(frames: int = 10, fps: float = 30.0, seed: int = 0) -> SmplMotion:
    """Small random poses, shape and a walk forward."""
    rng = np.random.default_rng(seed)
    pose = (0.25 * rng.normal(size=(frames, 24, 3))).astype(np.float32)
    trans = np.zeros((frames, 3), dtype=np.float32)
    trans[:, 2] = np.linspace(0.0, 0.5, frames)
    betas = (0.5 * rng.normal(size=10)).astype(np.float32)
    return SmplMotion(betas, pose, trans, fps)
