"""The trained model of one garment as a directory: the networks of the learned method (garment
VAE, pose codec, regressor) in one ``weights.safetensors``, and ``model.json`` with their
architectures, the model's version, the garment template it was trained on and the identity of
the body model it was trained for (a model is refused on another body).

``model.json`` also carries what a person needs to trust it: the command and configuration that
trained it, the training wall time and machine, and its held-out figures.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from usd_garment.atomic import atomic_output
from usd_garment.body.model import BodyModel
from usd_garment.generative.vae import GarmentVAE
from usd_garment.regressor.gru import GarmentRegressor
from usd_garment.regressor.pose_code import PoseCodec

#: Version of the directory layout.
MODEL_FORMAT = 1
CONFIG_NAME = "model.json"
WEIGHTS_NAME = "weights.safetensors"
#: The networks of a model and their classes.
PARTS: dict[str, type[torch.nn.Module]] = {
    "vae": GarmentVAE,
    "pose_codec": PoseCodec,
    "regressor": GarmentRegressor,
}


class ModelError(ValueError):
    """A model directory that cannot be used: missing, unreadable, or for another body."""


def body_fingerprint(body: BodyModel) -> str:
    """A short hash of what a trained model depends on in the body: rest vertices, faces, shape
    blendshapes, skinning weights and joint regressor (float32 bytes)."""
    digest = hashlib.sha256()
    for tensor in (body.v_template, body.faces, body.shapedirs, body.weights, body.J_regressor):
        digest.update(np.ascontiguousarray(tensor.detach().cpu().numpy()).tobytes())
    return digest.hexdigest()[:16]


@dataclass
class LearnedModel:
    """A trained garment model: its networks and ``model.json``'s metadata.

    Attributes:
        vae: the garment VAE (its decoder is used at run time, its encoder for training).
        pose_codec: the 10-d pose code.
        regressor: the GRU from motion descriptor and betas to latent codes.
        garment, lod: the template it was trained on; vertices: its N.
        version: the model's version, written to garment layers as ``garment:modelVersion``.
        body_name, body_fingerprint: the body model it was trained for.
        info: everything else of ``model.json`` (training command, config, wall time, machine,
            held-out figures).
    """

    vae: GarmentVAE
    pose_codec: PoseCodec
    regressor: GarmentRegressor
    garment: str
    lod: str
    vertices: int
    version: str
    body_name: str
    body_fingerprint: str
    info: dict[str, Any] = field(default_factory=dict)

    def parts(self) -> dict[str, torch.nn.Module]:
        return {name: getattr(self, name) for name in PARTS}

    def check_body(self, body: BodyModel) -> None:
        """Raise :class:`ModelError` unless ``body`` is the body the model was trained for."""
        found = body_fingerprint(body)
        if found != self.body_fingerprint:
            raise ModelError(
                f"the model was trained for the body '{self.body_name}' "
                f"({self.body_fingerprint}), not '{body.name}' ({found})"
            )


def save_learned_model(
    path: str | Path, model: LearnedModel, weights_dtype: torch.dtype = torch.float16
) -> None:
    """Write ``model`` into the directory ``path`` (created; other files there are kept): the
    weights, then ``model.json``, each written to a temporary file and renamed.

    Learned parameters are stored as ``weights_dtype`` (half the size in float16); buffers (the
    normalisation statistics, in metres) stay float32. Loading casts everything to float32.
    """
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    tensors = {}
    for name, part in model.parts().items():
        parameters = {key for key, _ in part.named_parameters()}
        for key, value in part.state_dict().items():
            value = value.detach().cpu()
            if key in parameters and value.is_floating_point():
                value = value.to(weights_dtype)
            tensors[f"{name}.{key}"] = value.contiguous()
    with atomic_output(path / WEIGHTS_NAME) as tmp:
        save_file(tensors, str(tmp))
    config = {
        "format": MODEL_FORMAT,
        "garment": model.garment,
        "lod": model.lod,
        "vertices": model.vertices,
        "version": model.version,
        "body": {"name": model.body_name, "fingerprint": model.body_fingerprint},
        "architecture": {name: part.config() for name, part in model.parts().items()},
        **model.info,
    }
    with atomic_output(path / CONFIG_NAME) as tmp:
        tmp.write_text(json.dumps(config, indent=1) + "\n", encoding="utf-8")


def load_learned_model(path: str | Path, body: BodyModel | None = None) -> LearnedModel:
    """Read the model directory ``path``; with ``body``, check it is the model's body.

    Raises:
        ModelError: no such directory, a file missing or unreadable, or another body.
    """
    path = Path(path)
    if not (path / CONFIG_NAME).is_file() or not (path / WEIGHTS_NAME).is_file():
        raise ModelError(f"{path}: not a model directory (needs {CONFIG_NAME}, {WEIGHTS_NAME})")
    try:
        config = json.loads((path / CONFIG_NAME).read_text(encoding="utf-8"))
        tensors = load_file(str(path / WEIGHTS_NAME))
    except (OSError, json.JSONDecodeError, SafetensorError) as exc:
        raise ModelError(f"{path}: unreadable model ({exc})") from None
    if not isinstance(config, dict) or config.get("format") != MODEL_FORMAT:
        raise ModelError(f"{path}: not a model of format {MODEL_FORMAT}")
    parts = {}
    try:
        for name, cls in PARTS.items():
            part = cls.from_config(config["architecture"][name])
            prefix = f"{name}."
            state = {
                k[len(prefix) :]: v.float() if v.is_floating_point() else v
                for k, v in tensors.items()
                if k.startswith(prefix)
            }
            part.load_state_dict(state)
            parts[name] = part.eval()
        meta = {k: config[k] for k in ("garment", "lod", "vertices", "version")}
        body_name, fingerprint = config["body"]["name"], config["body"]["fingerprint"]
    except (KeyError, TypeError, RuntimeError) as exc:
        raise ModelError(f"{path}: model files do not match ({exc})") from None
    info = {
        k: v
        for k, v in config.items()
        if k not in ("format", "garment", "lod", "vertices", "version", "body", "architecture")
    }
    model = LearnedModel(
        **parts, **meta, body_name=body_name, body_fingerprint=fingerprint, info=info
    )
    if body is not None:
        model.check_body(body)
    return model
