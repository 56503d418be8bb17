"""Short hashes of a body model, stored with what was computed for that body so that a file
made for another body is recognised.

Two hashes, because two kinds of file depend on different parts of the body: a garment template
on the rest surface and its skinning (``rest_fingerprint``), a trained model also on the shape
blendshapes and the joint regressor (``model_fingerprint``). Each is stored in committed files,
so neither may change what it hashes.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable

import numpy as np
import torch

from usd_garment.body.joints import NUM_BETAS
from usd_garment.body.model import BodyModel


def _digest(tensors: Iterable[torch.Tensor]) -> str:
    """The first 16 hex digits of the SHA-256 of the tensors' bytes, in order."""
    digest = hashlib.sha256()
    for tensor in tensors:
        digest.update(np.ascontiguousarray(tensor.detach().cpu().numpy()).tobytes())
    return digest.hexdigest()[:16]


def rest_fingerprint(body: BodyModel) -> str:
    """What a garment template depends on: the rest shape (β = 0 vertices ``(V, 3)``), faces
    and skinning weights."""
    with torch.no_grad():
        rest, _ = body.shaped(torch.zeros(1, NUM_BETAS))
    return _digest((rest[0], body.faces, body.weights))


def model_fingerprint(body: BodyModel) -> str:
    """What a trained model depends on: rest vertices, faces, shape blendshapes, skinning
    weights and joint regressor (float32 bytes)."""
    return _digest((body.v_template, body.faces, body.shapedirs, body.weights, body.J_regressor))
