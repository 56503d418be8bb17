"""Drape a garment template: let the cloth simulator settle it under gravity on the static rest
body (β = 0, T-pose), giving the draped template that simulations and the models start from.

The rest geometry (rest lengths, areas, bending) stays the template's; only the positions move.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS
from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.sim.checks import edge_lengths, unique_edges
from usd_garment.sim.cloth import ITERATIONS, SUBSTEPS, GarmentSimulator
from usd_garment.sim.material import ClothMaterial

#: Frames (at 30 fps) simulated at least and at most while draping.
MIN_FRAMES, MAX_FRAMES = 30, 90
#: The garment counts as settled once no vertex moves faster than this (m/s).
SETTLED_SPEED = 0.01


@dataclass
class DrapeResult:
    """A draped template and how it settled.

    Attributes:
        template: the draped template (same triangles, UVs and name as the input).
        frames: frames simulated.
        max_speed: fastest vertex speed over the last frame (m/s).
        settled: whether ``max_speed`` fell below the threshold.
        rest_length_error_median: median of |edge length / template edge length − 1|.
        rest_length_error_p99: its 99th percentile.
        inside_count: vertices with a negative signed distance to the rest body.
        clearance_min: smallest signed distance of a vertex to the rest body (m).
        clearance_median: median signed distance (m).
        sag: largest downward displacement of a vertex from the template (m).
    """

    template: GarmentTemplate
    frames: int
    max_speed: float
    settled: bool
    rest_length_error_median: float
    rest_length_error_p99: float
    inside_count: int
    clearance_min: float
    clearance_median: float
    sag: float

    def to_json(self) -> dict[str, object]:
        """The figures (not the mesh) as a JSON-ready dict."""
        return {
            "garment": self.template.name,
            "lod": self.template.lod,
            "vertices": len(self.template.vertices),
            "frames": self.frames,
            "max_speed_m_per_s": self.max_speed,
            "settled": self.settled,
            "rest_length_error_median": self.rest_length_error_median,
            "rest_length_error_p99": self.rest_length_error_p99,
            "inside_count": self.inside_count,
            "clearance_min_m": self.clearance_min,
            "clearance_median_m": self.clearance_median,
            "sag_m": self.sag,
        }


def rest_body(body: BodyModel) -> np.ndarray:
    """``(V, 3)`` float64 vertices of the body at β = 0 in the T-pose (m)."""
    with torch.no_grad():
        out = body(torch.zeros(NUM_BETAS), torch.zeros(1, NUM_JOINTS, 3))
    return out.vertices[0].double().numpy()


def drape_template(
    template: GarmentTemplate,
    body: BodyModel,
    *,
    material: ClothMaterial | None = None,
    substeps: int = SUBSTEPS,
    iterations: int = ITERATIONS,
    min_frames: int = MIN_FRAMES,
    max_frames: int = MAX_FRAMES,
    settled_speed: float = SETTLED_SPEED,
) -> DrapeResult:
    """Settle ``template`` under gravity on the static rest body of ``body``.

    Simulates at 30 fps from the template's shape until no vertex moves faster than
    ``settled_speed`` (after at least ``min_frames``), or ``max_frames``.

    Raises:
        ValueError: the simulation produced non-finite positions.
    """
    rest = np.asarray(template.vertices, dtype=np.float64)
    faces = np.asarray(template.faces, dtype=np.int64)
    body_rest = rest_body(body)
    sim = GarmentSimulator(
        rest, faces, body.faces.numpy(), body_rest, material,
        substeps=substeps, iterations=iterations,
    )  # fmt: skip
    previous = rest
    speed = float("inf")
    frames = 0
    while frames < max_frames and (frames < min_frames or speed > settled_speed):
        points = sim.step(body_rest).astype(np.float64)
        if not np.isfinite(points).all():
            raise ValueError(f"draping {template.name} ({template.lod}) gave non-finite positions")
        speed = float(np.linalg.norm(points - previous, axis=1).max() * sim.fps)
        previous = points
        frames += 1
    edges = unique_edges(faces)
    ratio = edge_lengths(previous, edges) / np.maximum(edge_lengths(rest, edges), 1e-12)
    error = np.abs(ratio - 1.0)
    sdf = sim.body_distance()
    draped = replace(template, vertices=previous.astype(np.float32))
    return DrapeResult(
        template=draped,
        frames=frames,
        max_speed=speed,
        settled=speed <= settled_speed,
        rest_length_error_median=float(np.median(error)),
        rest_length_error_p99=float(np.percentile(error, 99)),
        inside_count=int((sdf < 0).sum()),
        clearance_min=float(sdf.min()),
        clearance_median=float(np.median(sdf)),
        sag=float(np.max(rest[:, 1] - previous[:, 1])),
    )
