"""Procedural garment templates (T-shirt, dress) from a body model's rest shape.

Recipe: the inside of the rest body on a 5 mm grid, restricted by skinning weights to the
garment's body parts; a morphological closing so the cloth bridges concavities (a per-slice convex
hull with a flare below the hips for the skirt); the level set ``ease`` outside it extracted by
surface nets at the spacing that gives the level of detail's vertex count; openings cut by planes
placed from the joints; triangles relaxed on the level set and boundary loops laid on their planes.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError, cKDTree

from usd_garment.body.joints import NUM_BETAS, SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel
from usd_garment.garment.hull import FieldSampler, Grid, closing, inside_mesh, offset_field
from usd_garment.garment.mesh_ops import boundary_loops, cut, is_manifold, relax
from usd_garment.garment.surface_nets import surface_nets
from usd_garment.garment.template import GARMENT_NAMES, LODS, GarmentTemplate

#: Step (m) of the fine grid that holds the hull field.
FINE_SPACING = 0.005
#: Distance (m) between the closed body hull and the garment surface.
EASE = 0.012

_J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


@dataclass(frozen=True)
class Plane:
    """An opening: faces whose centroid is on the ``normal`` side of the plane are cut away."""

    name: str
    point: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class Recipe:
    """How one garment is made from a body's rest joints ``(24, 3)`` (m).

    Attributes:
        parts: joints whose skinned body parts (dominant skinning weight) the garment covers.
        planes: the openings, one boundary loop each.
        closing: radius (m) of the morphological closing that bridges concavities.
        skirt_top: height (m) below which each horizontal slice becomes its convex hull, or None.
        flare: outward growth (m per m below ``skirt_top``) of the skirt slices.
    """

    parts: tuple[str, ...]
    planes: tuple[Plane, ...]
    closing: float
    skirt_top: float | None = None
    flare: float = 0.0


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _neck_plane(j: np.ndarray) -> Plane:
    """Through the neck joint (above the collars), tilted 19° forward so the front dips lower."""
    return Plane("neck", j[_J["neck"]], _unit(np.array([0.0, 1.0, 0.35])))


def recipe(name: str, j: np.ndarray) -> Recipe:
    """The recipe of garment ``name`` for rest joints ``j`` ``(24, 3)`` (m)."""
    torso = ("pelvis", "spine1", "spine2", "spine3", "neck", "left_collar", "right_collar")
    arms = ("left_shoulder", "right_shoulder")
    hips = 0.5 * (j[_J["left_hip"]] + j[_J["right_hip"]])
    if name == "tshirt":
        sleeves = tuple(
            Plane(
                f"{side}_sleeve",
                0.5 * (j[_J[f"{side}_shoulder"]] + j[_J[f"{side}_elbow"]]),
                _unit(j[_J[f"{side}_elbow"]] - j[_J[f"{side}_shoulder"]]),
            )
            for side in ("left", "right")
        )
        waist = Plane("waist", hips, np.array([0.0, -1.0, 0.0]))
        return Recipe(
            (*torso, *arms, "left_hip", "right_hip"), (_neck_plane(j), waist, *sleeves), 0.03
        )
    if name == "dress":
        up = np.array([0.0, 1.0, 0.0])
        armholes = tuple(
            Plane(
                f"{side}_armhole",
                j[_J[f"{side}_shoulder"]],
                _unit(_unit(j[_J[f"{side}_elbow"]] - j[_J[f"{side}_shoulder"]]) + 0.4 * up),
            )
            for side in ("left", "right")
        )
        knees = 0.5 * (j[_J["left_knee"]] + j[_J["right_knee"]])
        hem = Plane("hem", knees, np.array([0.0, -1.0, 0.0]))
        legs = ("left_hip", "right_hip", "left_knee", "right_knee")
        return Recipe(
            (*torso, *arms, *legs),
            (_neck_plane(j), *armholes, hem),
            0.04,
            skirt_top=float(hips[1]),
            flare=0.12,
        )
    raise ValueError(f"unknown garment '{name}' (known: {', '.join(GARMENT_NAMES)})")


def rest_body(body: BodyModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The body at β = 0: vertices ``(V, 3)``, faces ``(F, 3)``, joints ``(24, 3)`` (m) and
    each vertex's dominant joint ``(V,)``."""
    with torch.no_grad():
        v, j = body.shaped(torch.zeros(1, NUM_BETAS))
    return (
        v[0].double().numpy(),
        body.faces.numpy(),
        j[0].double().numpy(),
        body.weights.argmax(1).numpy(),
    )


@dataclass
class Hull:
    """A garment's level-set field on the fine grid, with the planes of its openings."""

    planes: tuple[Plane, ...]
    sampler: FieldSampler


def build_hull(
    vertices: np.ndarray, faces: np.ndarray, joints: np.ndarray, owner: np.ndarray, name: str
) -> Hull:
    """The level-set field of garment ``name`` around a rest body.

    Args:
        vertices: ``(V, 3)`` rest vertices (m); faces: ``(F, 3)``; joints: ``(24, 3)`` (m);
        owner: ``(V,)`` dominant joint of each vertex.
    """
    rec = recipe(name, joints)
    part = np.isin(owner, [_J[p] for p in rec.parts])
    lo, hi = vertices[part].min(0), vertices[part].max(0)
    margin = rec.closing + EASE + 0.03
    for plane in rec.planes:  # nothing is needed far beyond a horizontal cut
        if abs(plane.normal[1]) == 1.0:
            if plane.normal[1] < 0:
                lo[1] = max(lo[1], plane.point[1] - margin)
            else:
                hi[1] = min(hi[1], plane.point[1] + margin)
    skirt_depth = 0.0 if rec.skirt_top is None else rec.skirt_top - lo[1]
    pad = EASE + 0.03 + rec.flare * max(skirt_depth, 0.0)
    grid = Grid.covering(lo - pad, hi + pad, FINE_SPACING)
    solid = inside_mesh(vertices, faces, grid)
    idx = np.argwhere(solid)
    pts = grid.points(idx)
    _, nearest = cKDTree(vertices).query(pts)
    keep = part[nearest] & np.all((pts >= lo) & (pts <= hi), axis=1)
    solid[:] = False
    solid[tuple(idx[keep].T)] = True
    if rec.skirt_top is not None:
        solid = _skirt(solid, grid, rec.skirt_top, rec.flare)
    solid = closing(solid, grid.spacing, rec.closing)
    field = offset_field(solid, grid.spacing, EASE, smooth=1.5 * grid.spacing)
    planes = tuple(
        _clear_shoulders(p, field, grid, joints) if p.name == "neck" else p for p in rec.planes
    )
    return Hull(planes, FieldSampler(field, grid))


def _clear_shoulders(neck: Plane, field: np.ndarray, grid: Grid, joints: np.ndarray) -> Plane:
    """Raise the neck plane (along its normal) until it no longer cuts the garment away from the
    neck: nothing farther than 70% of the neck-to-shoulder distance from the neck axis may lie
    above it, with a 1 cm margin."""
    radius = 0.7 * np.linalg.norm((joints[_J["left_shoulder"]] - joints[_J["neck"]])[[0, 2]])
    pts = grid.points(np.argwhere(field < 0))
    far = np.linalg.norm((pts - neck.point)[:, [0, 2]], axis=1) > radius
    height = (pts[far] - neck.point) @ neck.normal
    lift = height.max() + 0.01 if len(height) else 0.0
    if lift <= 0:
        return neck
    return Plane(neck.name, neck.point + lift * neck.normal, neck.normal)


def _skirt(solid: np.ndarray, grid: Grid, top: float, flare: float) -> np.ndarray:
    """Replace each horizontal slice below ``top`` (m) by its convex hull grown by
    ``flare * (top - y)`` (m)."""
    out = solid.copy()
    ys = grid.axis(1)
    ii, kk = np.meshgrid(np.arange(grid.shape[0]), np.arange(grid.shape[2]), indexing="ij")
    cells = np.stack([ii.ravel(), kk.ravel()], 1).astype(np.float64)
    for j in np.nonzero(ys < top)[0]:
        occupied = np.argwhere(solid[:, j, :]).astype(np.float64)
        if len(occupied) < 4:
            continue
        try:
            hull = ConvexHull(occupied)
        except QhullError:
            continue
        a, b = hull.equations[:, :2], hull.equations[:, 2]
        filled = ((cells @ a.T + b) <= 1e-9).all(1).reshape(ii.shape)
        grow = flare * (top - ys[j]) / grid.spacing
        if grow > 0:
            filled = ndimage.distance_transform_edt(~filled) <= grow
        out[:, j, :] = filled
    return out


def extract(hull: Hull, target: int, tries: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """The cut, relaxed garment mesh with about ``target`` vertices: vertices ``(N, 3)`` (m),
    faces ``(F, 3)``; 2-manifold, one component, one boundary loop per opening.

    The surface-nets spacing is refined from the vertex count it gives; a result that is not
    manifold or has the wrong openings is retried on a shifted grid.

    Raises:
        ValueError: no acceptable mesh within ``tries`` extractions (an unusual body).
    """
    sampler, planes = hull.sampler, hull.planes
    grid = sampler.grid
    extent = grid.spacing * (np.array(grid.shape) - 1)
    spacing = 0.015 * np.sqrt(4400 / target)
    shift = np.zeros(3)
    best: tuple[np.ndarray, np.ndarray] | None = None
    for _ in range(tries):
        coarse = Grid.covering(grid.origin - shift, grid.origin + extent, spacing)
        axes = np.meshgrid(*(coarse.axis(i) for i in range(3)), indexing="ij")
        pts = np.stack([a.ravel() for a in axes], 1)
        field = sampler.value(pts).reshape(coarse.shape)
        v, f = surface_nets(field, coarse.origin, coarse.spacing)
        v, f = cut(v, f, [(p.point, p.normal) for p in planes])
        if not is_manifold(f) or len(boundary_loops(f)) != len(planes):
            shift = (shift + np.array([0.31, 0.37, 0.23]) * spacing) % spacing
            continue
        if best is None or abs(len(v) - target) < abs(len(best[0]) - target):
            best = (v, f)
        if abs(len(v) - target) <= 0.02 * target:
            break
        spacing *= np.sqrt(len(v) / target)
    if best is None:
        raise ValueError("no manifold garment mesh with one loop per opening for this body")
    v, f = best
    points = np.stack([p.point for p in planes])
    normals = np.stack([p.normal for p in planes])

    def on_plane(p: np.ndarray) -> np.ndarray:
        nearest = np.abs(np.einsum("ikj,kj->ik", p[:, None] - points, normals)).argmin(1)
        for _ in range(3):
            d = np.einsum("ij,ij->i", p - points[nearest], normals[nearest])
            p = sampler.project(p - d[:, None] * normals[nearest], 2)
        return p

    v = relax(v, f, lambda p: sampler.project(p, 3), on_plane, iterations=40)
    return v, f


def planar_uvs(vertices: np.ndarray, center_z: float) -> np.ndarray:
    """UVs ``(N, 2)`` in [0, 1]: front (z ≥ ``center_z``) and back projected onto XY side by side.

    The front half fills u in [0, 0.5], the back (mirrored, as seen from behind) u in [0.5, 1];
    one scale for both axes keeps the aspect ratio.
    """
    lo, hi = vertices.min(0), vertices.max(0)
    scale = 1.0 / max(2.0 * (hi[0] - lo[0]), hi[1] - lo[1])
    x = (vertices[:, 0] - lo[0]) * scale
    y = (vertices[:, 1] - lo[1]) * scale
    back = vertices[:, 2] < center_z
    u = np.where(back, 1.0 - x, x)
    return np.clip(np.stack([u, y], 1), 0.0, 1.0).astype(np.float32)


def build_templates(
    body: BodyModel, name: str, lods: tuple[str, ...] = tuple(LODS)
) -> Iterator[GarmentTemplate]:
    """Templates of garment ``name`` for ``body``, one per level of detail in ``lods``, in order.

    The hull is built once, before the first template is yielded.

    Raises:
        ValueError: unknown garment name or level of detail.
    """
    for lod in lods:
        if lod not in LODS:
            raise ValueError(f"unknown level of detail '{lod}' (known: {', '.join(LODS)})")
    vertices, faces, joints, owner = rest_body(body)
    hull = build_hull(vertices, faces, joints, owner, name)
    center_z = float(joints[[_J["pelvis"], _J["spine3"]], 2].mean())
    for lod in lods:
        v, f = extract(hull, LODS[lod])
        uvs = planar_uvs(v, center_z)
        yield GarmentTemplate(name, lod, v.astype(np.float32), f.astype(np.int32), uvs, body.name)


def make_template(body: BodyModel, name: str, lod: str) -> GarmentTemplate:
    """The template of garment ``name`` at level of detail ``lod`` for ``body``'s rest shape."""
    return next(build_templates(body, name, (lod,)))
