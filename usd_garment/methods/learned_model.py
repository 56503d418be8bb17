"""The trained model of one garment as a directory: the networks of the learned method (garment
VAE, pose codec, regressor) in one ``weights.safetensors``, and ``model.json`` with their
architectures, the model's version, the garment template it was trained on and the identity of
the body model it was trained for (a model is refused on another body).

A model holds one or more *members*, each a full set of those networks trained on its own (other
seeds, other sizes): the model's garment is the mean of the members' canonical garments, posed
once (an ensemble; :func:`combine_models` makes one from trained models).

A model may smooth its latent codes in time before decoding (``latent_smoothing_s``: the standard
deviation, in seconds, of a Gaussian over the codes at the model's 30 fps; 0, no smoothing), and
its posed garment before any push-out (``posed_smoothing_s``: the same over the posed vertices at
the input's frame rate; 0, none; the networks alone, ``learned``, leave it out:
``LearnedMethod.smooths``).

``model.json`` also carries what a person needs to trust it: the command and configuration that
trained it (each member's, for an ensemble), the training wall time and machine, and its
held-out figures. Beside them, a trained model keeps its training curves and log (an ensemble,
each member's).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from usd_garment.atomic import atomic_output
from usd_garment.body.fingerprint import model_fingerprint
from usd_garment.body.model import BodyModel
from usd_garment.generative.vae import GarmentVAE
from usd_garment.methods.weight_storage import check_storage, restored, stored
from usd_garment.regressor.gru import GarmentRegressor
from usd_garment.regressor.pose_code import PoseCodec

#: Version of the directory layout by the storage of its weights: 2 has a list of members and
#: float16 weights; 3 is 2 with int8 weights and their row scales (``weight_storage``); 1 (one
#: member, the networks' architectures under "architecture" and their weights unprefixed) is
#: still read.
MODEL_FORMATS = {"float16": 2, "int8": 3}
READ_FORMATS = (1, 2, 3)
#: The keys of ``model.json`` that describe the layout rather than the model's history.
_LAYOUT_KEYS = frozenset(
    ("format", "weights", "garment", "lod", "vertices", "version", "body", "architecture",
     "members", "latent_smoothing_s", "posed_smoothing_s")
)  # fmt: skip
#: The keys of ``model.json`` that hold smoothings in time (s); a model written before one was
#: added has none (0).
SMOOTHING_KEYS = ("latent_smoothing_s", "posed_smoothing_s")
CONFIG_NAME = "model.json"
WEIGHTS_NAME = "weights.safetensors"
#: A training run's pictures and plain-text log beside its model files; an ensemble keeps its
#: members' as ``curves_member{i}.png`` and ``train_member{i}.log``.
CURVES_NAME = "curves.png"
LOG_NAME = "train.log"
#: The networks of a model and their classes.
PARTS: dict[str, type[torch.nn.Module]] = {
    "vae": GarmentVAE,
    "pose_codec": PoseCodec,
    "regressor": GarmentRegressor,
}


class ModelError(ValueError):
    """A model directory that cannot be used: missing, unreadable, or for another body."""


@dataclass
class Member:
    """One trained set of the learned method's networks.

    Attributes:
        vae: the garment VAE (its decoder is used at run time, its encoder for training).
        pose_codec: the 10-d pose code.
        regressor: the GRU from motion descriptor and betas to latent codes.
        info: what ``model.json`` says of this member alone (in an ensemble: the command,
            configuration and figures of the model it came from); empty for a model of one.
    """

    vae: GarmentVAE
    pose_codec: PoseCodec
    regressor: GarmentRegressor
    info: dict[str, Any] = field(default_factory=dict)

    def parts(self) -> dict[str, torch.nn.Module]:
        return {name: getattr(self, name) for name in PARTS}


@dataclass
class LearnedModel:
    """A trained garment model: its networks (one member, or several averaged) and
    ``model.json``'s metadata.

    Attributes:
        members: the trained networks; the model's canonical garment is their decodings' mean.
        garment, lod: the template it was trained on; vertices: its N.
        version: the model's version, written to garment layers as ``garment:modelVersion``.
        body_name, body_fingerprint: the body model it was trained for.
        latent_smoothing: standard deviation (s) of the Gaussian that smooths the codes in time
            before decoding (:func:`~usd_garment.methods.learned.predict_latents`); 0: none.
        posed_smoothing: standard deviation (s) of the Gaussian that smooths the posed garment
            in time before it is pushed out of the body
            (:class:`~usd_garment.methods.learned_posing.Smoothing`); 0: none.
        info: everything else of ``model.json`` (training command, config, wall time, machine,
            held-out figures).
    """

    members: list[Member]
    garment: str
    lod: str
    vertices: int
    version: str
    body_name: str
    body_fingerprint: str
    latent_smoothing: float = 0.0
    posed_smoothing: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def latent_sizes(self) -> list[int]:
        """Each member's latent size L_m; the model's codes ``(T, ΣL_m)`` are theirs side by
        side."""
        return [member.vae.latent_size for member in self.members]

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Canonical garments ``(T, N, 3)`` (m) of the codes ``z`` ``(T, ΣL_m)``: each member
        decodes its own codes, and the decodings are averaged."""
        codes = z.split(self.latent_sizes, dim=1)
        total = self.members[0].vae.decode(codes[0])
        for member, code in zip(self.members[1:], codes[1:], strict=True):
            total = total + member.vae.decode(code)
        return total / len(self.members)

    def check_body(self, body: BodyModel) -> None:
        """Raise :class:`ModelError` unless ``body`` is the body the model was trained for."""
        found = model_fingerprint(body)
        if found != self.body_fingerprint:
            raise ModelError(
                f"the model was trained for the body '{self.body_name}' "
                f"({self.body_fingerprint}), not '{body.name}' ({found})"
            )


def save_learned_model(path: str | Path, model: LearnedModel, weights: str = "float16") -> None:
    """Write ``model`` into the directory ``path`` (created; other files there are kept): the
    weights, then ``model.json``, each written to a temporary file and renamed.

    Learned parameters are stored as ``weights`` (one of ``weight_storage.STORAGES``: float16,
    half the size of float32; int8, about a quarter); buffers (the normalisation statistics, in
    metres) stay float32. Loading gives everything as float32.

    Raises:
        ValueError: an unknown ``weights``.
    """
    check_storage(weights)
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    tensors = {}
    for index, member in enumerate(model.members):
        for name, part in member.parts().items():
            parameters = {key for key, _ in part.named_parameters()}
            for key, value in part.state_dict().items():
                value, full = value.detach().cpu(), f"{index}.{name}.{key}"
                if key in parameters and value.is_floating_point():
                    tensors.update(stored(full, value, weights))
                else:
                    tensors[full] = value
    tensors = {key: value.contiguous() for key, value in tensors.items()}
    with atomic_output(path / WEIGHTS_NAME) as tmp:
        save_file(tensors, str(tmp))
    members = [
        {"architecture": {name: part.config() for name, part in member.parts().items()}}
        | member.info
        for member in model.members
    ]
    config = {
        "format": MODEL_FORMATS[weights],
        "weights": weights,
        "garment": model.garment,
        "lod": model.lod,
        "vertices": model.vertices,
        "version": model.version,
        "body": {"name": model.body_name, "fingerprint": model.body_fingerprint},
        "latent_smoothing_s": model.latent_smoothing,
        "posed_smoothing_s": model.posed_smoothing,
        "members": members,
        **model.info,
    }
    with atomic_output(path / CONFIG_NAME) as tmp:
        tmp.write_text(json.dumps(config, indent=1) + "\n", encoding="utf-8")


def model_identity(path: str | Path) -> dict[str, str]:
    """What names the trained weights of the model directory ``path``: its ``version`` and
    ``weights``, the first 16 hex digits of the SHA-256 of its weights file (two models with the
    same version string but other weights differ there).

    Raises:
        ModelError: not a model directory, or unreadable.
    """
    path = Path(path)
    try:
        version = str(json.loads((path / CONFIG_NAME).read_text(encoding="utf-8"))["version"])
        digest = hashlib.sha256((path / WEIGHTS_NAME).read_bytes()).hexdigest()[:16]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ModelError(f"{path}: not a readable model directory ({exc})") from None
    return {"version": version, "weights": digest}


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
    if not isinstance(config, dict) or config.get("format") not in READ_FORMATS:
        raise ModelError(f"{path}: not a model of format {' or '.join(map(str, READ_FORMATS))}")
    try:
        if config["format"] == 1:
            entries, prefixes = [{"architecture": config["architecture"]}], [""]
        else:
            entries = config["members"]
            prefixes = [f"{index}." for index in range(len(entries))]
        tensors = restored(tensors)
        members = [
            _load_member(entry, tensors, prefix)
            for entry, prefix in zip(entries, prefixes, strict=True)
        ]
        meta = {k: config[k] for k in ("garment", "lod", "vertices", "version")}
        body_name, fingerprint = config["body"]["name"], config["body"]["fingerprint"]
        smoothing = {k: float(config.get(k, 0.0)) for k in SMOOTHING_KEYS}
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise ModelError(f"{path}: model files do not match ({exc})") from None
    for key, seconds in smoothing.items():
        _check_smoothing(seconds, f"{path}: ", key)
    if not members:
        raise ModelError(f"{path}: a model with no members")
    info = {k: v for k, v in config.items() if k not in _LAYOUT_KEYS}
    model = LearnedModel(
        members,
        **meta,
        body_name=body_name,
        body_fingerprint=fingerprint,
        latent_smoothing=smoothing["latent_smoothing_s"],
        posed_smoothing=smoothing["posed_smoothing_s"],
        info=info,
    )
    if body is not None:
        model.check_body(body)
    return model


def _check_smoothing(seconds: float, where: str = "", key: str = "latent_smoothing_s") -> None:
    """Raise :class:`ModelError` unless ``seconds`` is a usable smoothing (``model.json``'s
    ``key``): finite and ≥ 0 (``where`` prefixes the message)."""
    if not (np.isfinite(seconds) and seconds >= 0):
        raise ModelError(f"{where}{key} must be a finite number ≥ 0, not {seconds}")


def _load_member(entry: dict[str, Any], tensors: dict[str, torch.Tensor], prefix: str) -> Member:
    """The member that ``model.json``'s ``entry`` describes, its weights those of ``tensors``
    (restored to float32: ``weight_storage.restored``) under ``prefix``."""
    parts = {}
    for name, cls in PARTS.items():
        # Made on the meta device, its tensors then the stored ones (assign): no random
        # initialization of weights about to be replaced (130 tensors, about half of a load of
        # the five-member T-shirt). strict: a tensor missing from the file is an error, so no
        # meta tensor is left.
        with torch.device("meta"):
            part = cls.from_config(entry["architecture"][name])
        head = f"{prefix}{name}."
        state = {k[len(head) :]: v for k, v in tensors.items() if k.startswith(head)}
        part.load_state_dict(state, assign=True)
        parts[name] = part.eval()
    info = {k: v for k, v in entry.items() if k != "architecture"}
    return Member(**parts, info=info)  # type: ignore[arg-type]


def combine_models(
    paths: list[str | Path],
    version: str | None = None,
    latent_smoothing: float = 0.0,
    posed_smoothing: float = 0.0,
) -> LearnedModel:
    """One model whose members are those of the model directories ``paths`` (an ensemble: its
    garment is the mean of theirs). Each member keeps what its model's ``model.json`` said of
    it (command, training, figures) and where it came from; the combined model's own ``info``
    starts empty (the caller records how it was combined).

    Args:
        version: the combined model's version (None: the first model's, with ``-ensemble``).
        latent_smoothing: the combined model's :attr:`LearnedModel.latent_smoothing` (s).
        posed_smoothing: its :attr:`LearnedModel.posed_smoothing` (s).

    Raises:
        ModelError: fewer than two models, an unreadable one, models of another garment,
            level of detail or body than the first, or a negative smoothing.
    """
    if len(paths) < 2:
        raise ModelError("combining needs at least two models")
    _check_smoothing(latent_smoothing)
    _check_smoothing(posed_smoothing, key="posed_smoothing_s")
    models = [load_learned_model(path) for path in paths]
    first = models[0]
    members = []
    for path, model in zip(paths, models, strict=True):
        if (model.garment, model.lod, model.vertices) != (first.garment, first.lod, first.vertices):
            raise ModelError(
                f"{path}: a model of the {model.lod} {model.garment} ({model.vertices} vertices), "
                f"not the {first.lod} {first.garment} ({first.vertices}) of {paths[0]}"
            )
        if model.body_fingerprint != first.body_fingerprint:
            raise ModelError(
                f"{path}: trained for the body '{model.body_name}' ({model.body_fingerprint}), "
                f"not '{first.body_name}' ({first.body_fingerprint}) as {paths[0]}"
            )
        for member in model.members:
            source = member.info or {**model.info, "version": model.version}
            members.append(replace(member, info={"source": str(path), **source}))
    return LearnedModel(
        members,
        garment=first.garment,
        lod=first.lod,
        vertices=first.vertices,
        version=version if version is not None else f"{first.version}-ensemble",
        body_name=first.body_name,
        body_fingerprint=first.body_fingerprint,
        latent_smoothing=latent_smoothing,
        posed_smoothing=posed_smoothing,
    )


def _member_name(name: str, index: int) -> str:
    """``curves.png`` → ``curves_member{index}.png`` (likewise ``train.log``)."""
    stem, suffix = name.rsplit(".", 1)
    return f"{stem}_member{index}.{suffix}"


def member_model(model: LearnedModel, index: int) -> LearnedModel:
    """The one-member model of ``model``'s member ``index`` (0-based), to run or bench it alone:
    its networks and record, ``model``'s garment, body and smoothings, version
    ``{version}-member{index}``, its own ``info`` empty (the caller records how it was made).

    Raises:
        ModelError: no such member.
    """
    count = len(model.members)
    if not 0 <= index < count:
        raise ModelError(f"no member {index}: the model has {count} (0 to {count - 1})")
    version = f"{model.version}-member{index}"
    return replace(model, members=[model.members[index]], version=version, info={})


def _member_count(path: Path) -> int:
    """How many members the model directory ``path`` holds, from its ``model.json`` alone."""
    config = json.loads((path / CONFIG_NAME).read_text(encoding="utf-8"))
    return 1 if config["format"] == 1 else len(config["members"])


def _copy_member_files(path: Path, member: int, count: int, out: Path, index: int | None) -> int:
    """Copy the training curves and log of member ``member`` of the model directory ``path`` (of
    ``count`` members) into ``out``, each through a temporary file renamed: as
    ``curves_member{index}.png`` and ``train_member{index}.log``, or with ``index`` None as a
    ``train all`` run's ``curves.png`` and ``train.log``. A member's files are its numbered ones,
    or for a one-member model (a ``train all`` run) the plain names. Returns how many were
    copied (a missing file is skipped)."""
    copied = 0
    for name in (CURVES_NAME, LOG_NAME):
        sources = [path / _member_name(name, member)] + ([path / name] if count == 1 else [])
        source = next((s for s in sources if s.is_file()), None)
        if source is not None:
            target = out / (name if index is None else _member_name(name, index))
            with atomic_output(target) as tmp:
                tmp.write_bytes(source.read_bytes())
            copied += 1
    return copied


def copy_member_records(paths: list[str | Path], out: str | Path) -> int:
    """Copy the training curves and logs of the members of the models ``paths`` into the combined
    model directory ``out`` (existing), numbered as :func:`combine_models` numbers the members:
    ``curves_member{i}.png`` and ``train_member{i}.log``. Returns how many files were copied (a
    member without them is skipped).
    """
    copied, index = 0, 0
    for path in map(Path, paths):
        count = _member_count(path)
        for member in range(count):
            copied += _copy_member_files(path, member, count, Path(out), index)
            index += 1
    return copied


def copy_member_record(path: str | Path, index: int, out: str | Path) -> int:
    """Copy the training curves and log of member ``index`` of the model ``path`` into the
    one-member model directory ``out`` (existing) as ``curves.png`` and ``train.log``, the names
    of a ``train all`` run. Returns how many files were copied."""
    path = Path(path)
    return _copy_member_files(path, index, _member_count(path), Path(out), None)
