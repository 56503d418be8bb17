"""Flat-shaded orthographic drawings of meshes on matplotlib axes (painter's algorithm), for
previews and contact sheets; matplotlib is imported by the caller (an optional dependency)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

LIGHT = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
SKIN = (0.85, 0.65, 0.5)
CLOTH = (0.25, 0.45, 0.75)


def view_axes(view_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Screen-right and towards-viewer unit vectors ``(3,)`` for a camera turned ``view_deg``
    degrees from the front (+Z) towards the body's left (+X), looking horizontally."""
    angle = np.radians(view_deg)
    right = np.array([np.cos(angle), 0.0, -np.sin(angle)])
    towards = np.array([np.sin(angle), 0.0, np.cos(angle)])
    return right, towards


def draw_meshes(
    ax: Any,
    meshes: Sequence[tuple[np.ndarray, np.ndarray, tuple[float, float, float]]],
    view_deg: float = 0.0,
) -> None:
    """Draw ``(vertices (V, 3) m, faces (F, 3), rgb)`` meshes, depth-sorted together, projected
    on (screen-right, +Y). Back faces are dropped, so open garments show their outside only."""
    from matplotlib.collections import PolyCollection

    right, towards = view_axes(view_deg)
    polys, colours, depths = [], [], []
    for vertices, faces, rgb in meshes:
        tri = np.asarray(vertices, dtype=np.float64)[faces]  # (F, 3, 3)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
        front = normal @ towards > 0.0
        tri, normal = tri[front], normal[front]
        shade = 0.25 + 0.75 * np.clip(normal @ LIGHT, 0.0, 1.0)
        polys.append(np.stack([tri @ right, tri[..., 1]], axis=-1))
        colours.append(shade[:, None] * np.asarray(rgb))
        depths.append(tri.mean(axis=1) @ towards)
    order = np.argsort(np.concatenate(depths))
    xy = np.concatenate(polys)[order]
    colour = np.concatenate(colours)[order]
    ax.add_collection(PolyCollection(xy, facecolors=colour, edgecolors=colour, linewidths=0.2))
