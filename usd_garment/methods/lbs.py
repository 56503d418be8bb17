"""Skinning baselines: the garment template skinned with the weights and shape blendshapes of its
nearest rest-body vertex (TailorNet / Santesteban-2019 style), with and without push-out."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import torch
from scipy.spatial import cKDTree

from usd_garment.body.lbs import blend_shapes, skin
from usd_garment.body.model import BodyModel
from usd_garment.eval.body_distance import BodySurface, body_pool
from usd_garment.eval.push_out import PUSH_OUT_EPS, PUSH_OUT_PASSES, push_out
from usd_garment.garment.template import GarmentTemplate
from usd_garment.methods.base import Progress, predict_chunks
from usd_garment.motion.sequence import SmplMotion

#: Frames posed at once (bounds memory: the body pass holds ~V·12 floats per frame).
FRAMES_PER_CHUNK = 128


def nearest_body_vertex(body: BodyModel, template: GarmentTemplate) -> np.ndarray:
    """Index ``(N,)`` of the nearest vertex of the rest body at β = 0 for each garment vertex."""
    tree = cKDTree(body.v_template.numpy())
    return tree.query(np.asarray(template.vertices, dtype=np.float64))[1]


class LbsMethod:
    """Static nearest-vertex skinning (no collision handling)."""

    name = "lbs"
    version = "1"
    push_out = False
    #: Processes that push the garment out (one CPU core each; 1: this process).
    push_out_workers = 1
    settings: dict[str, float | int | str] = {}  # noqa: RUF012 (read-only)

    @property
    def pushes_vertices(self) -> bool:
        """Whether the posed vertices are pushed out of the body (``base.pushes_vertices``)."""
        return self.push_out

    def predict(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        progress: Progress | None = None,
    ) -> np.ndarray:
        """Posed garment points ``(T, N, 3)`` float32, canonical frame (m)."""
        chunks = predict_chunks(self, motion, body, template, FRAMES_PER_CHUNK, progress)
        return np.concatenate(list(chunks))

    def predict_stream(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        chunk: int = FRAMES_PER_CHUNK,
    ) -> Iterator[np.ndarray]:
        """Posed garment points in consecutive chunks ``(t ≤ chunk, N, 3)`` float32 (m)."""
        idx = torch.from_numpy(nearest_body_vertex(body, template))
        weights = body.weights[idx]  # (N, J)
        betas = torch.as_tensor(motion.betas, dtype=torch.float32)[None]
        rest = torch.as_tensor(template.vertices, dtype=torch.float32)[None]
        rest = rest + blend_shapes(betas, body.shapedirs[idx])  # (1, N, 3)
        surface = BodySurface(body.faces.numpy(), body.num_vertices) if self.push_out else None
        pose = torch.as_tensor(motion.pose, dtype=torch.float32)
        trans = torch.as_tensor(motion.trans, dtype=torch.float32)
        with body_pool(self.push_out_workers if self.push_out else 1) as pool:
            for s in range(0, motion.num_frames, chunk):
                e = min(s + chunk, motion.num_frames)
                with torch.no_grad():
                    posed = body(betas[0], pose[s:e], trans[s:e])
                    points = skin(rest.expand(e - s, -1, -1), weights, posed.transforms).numpy()
                if surface is not None:
                    points = push_out(points, posed.vertices.numpy(), surface, pool=pool)
                yield points.astype(np.float32, copy=False)


class LbsPushOutMethod(LbsMethod):
    """Nearest-vertex skinning, then vertices inside or near the body pushed out to ε = 2 mm."""

    name = "lbs+postprocess"
    push_out = True
    settings: dict[str, float | int | str] = {  # noqa: RUF012 (read-only)
        "push_out_eps_m": PUSH_OUT_EPS,
        "push_out_passes": PUSH_OUT_PASSES,
    }
