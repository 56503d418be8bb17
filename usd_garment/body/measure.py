"""Summary figures of a body model: counts, joint names and heights over the first shape axis."""

from __future__ import annotations

from typing import Any

import torch

from usd_garment.body.joints import NUM_BETAS, SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel


def heights(model: BodyModel, betas: torch.Tensor) -> torch.Tensor:
    """Standing heights ``(B,)`` (m, extent along +Y in rest pose) for betas ``(B, 10)``."""
    v_shaped, _ = model.shaped(betas)
    y = v_shaped[..., 1]
    return y.amax(dim=1) - y.amin(dim=1)


def body_summary(model: BodyModel) -> dict[str, Any]:
    """Counts, joint names, height at β = 0 and the height range over β₁ ∈ [−2, 2]."""
    betas = torch.zeros(5, NUM_BETAS)
    betas[:, 0] = torch.linspace(-2.0, 2.0, 5)
    with torch.no_grad():
        h = heights(model, betas)
        h0 = heights(model, torch.zeros(1, NUM_BETAS))[0]
    return {
        "name": model.name,
        "vertices": model.num_vertices,
        "faces": int(model.faces.shape[0]),
        "joints": len(SMPL_JOINT_NAMES),
        "joint_names": list(SMPL_JOINT_NAMES),
        "pose_blendshapes": model.has_pose_blendshapes,
        "height_m": round(float(h0), 4),
        "height_range_beta1_m": [round(float(h.min()), 4), round(float(h.max()), 4)],
        "height_at_beta1_m": {
            f"{b:+.0f}": round(float(x), 4) for b, x in zip(betas[:, 0], h, strict=True)
        },
    }
