"""How close a model trained on a canonical set can come to its simulations.

A learned model predicts canonical garments X and poses them with the garment model M_G(X, β, θ);
at best it reproduces the set's own targets. Posing those targets back (M_G of the projected X of
each frame) and measuring them like a method's output against the posed body gives a floor under
any such model's figures: the collisions that the canonical representation itself leaves (where
no X poses onto the simulated cloth: the reprojection error's tail, and the collision term that
keeps X out of the canonical body), beside the simulation's own.

For a trained model, :func:`network_floor` splits its error on the same targets in canonical
space: the decoder's best fit (the latent codes that come closest, :func:`fit_latents`: what the
subspace can represent) against the regressor's codes decoded (what the networks predict).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from usd_garment.body.model import BodyModel
from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.eval.metrics import evaluate_garment
from usd_garment.fields.body_fields import BodyFields
from usd_garment.garment.model import GarmentModel
from usd_garment.generative.fit import fit_latents
from usd_garment.methods.learned import predict_latents
from usd_garment.methods.learned_model import LearnedModel
from usd_garment.usd.garment_read import read_garment_layer

#: Frames posed at once (bounds the ``(t, N, channels)`` temporaries of M_G).
POSE_FRAMES = 64


@dataclass(frozen=True)
class SequenceFloor:
    """Figures of one sequence of a canonical set (means over its frames).

    Attributes:
        source: the simulated garment layer.
        split: "train", "validation" or "test".
        frames: frames of the sequence.
        reprojection_mm: mean per-vertex distance from M_G(X) to the simulation (mm).
        simulation: ``GarmentMetrics.summary()`` of the simulated garment.
        reposed: ``GarmentMetrics.summary()`` of M_G(X), the targets posed back.
    """

    source: str
    split: str
    frames: int
    reprojection_mm: float
    simulation: dict[str, Any]
    reposed: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class NetworkFloor:
    """A trained model's canonical-space error on one sequence of a canonical set (means over
    its frames and vertices, mm).

    Attributes:
        source, split, frames: as :class:`SequenceFloor`'s.
        decoder_fit_mm: distance from the decoder's best fit to the targets X.
        networks_mm: distance from the decoded regressor codes to X.
    """

    source: str
    split: str
    frames: int
    decoder_fit_mm: float
    networks_mm: float

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _chosen(data: CanonicalSet, splits: Sequence[str] | None) -> list[int]:
    return [s for s in range(data.num_sequences) if splits is None or data.splits[s] in splits]


def network_floor(
    data: CanonicalSet,
    model: LearnedModel,
    splits: Sequence[str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[NetworkFloor]:
    """The decoder's best fit and the networks' prediction of each sequence of ``data`` in
    ``splits`` (all by default), against its targets, in canonical space; the fit starts from
    the regressor's codes.

    Raises:
        ValueError: the model's garment has another vertex count than the set's.
    """
    if model.vertices != data.canonical.shape[1]:
        raise ValueError(
            f"the model is of {model.vertices} vertices, the set's garments "
            f"{data.canonical.shape[1]}"
        )
    out = []
    for done, s in enumerate(_chosen(data, splits), 1):
        frames = data.sequence(s)
        x = torch.as_tensor(data.canonical[frames]).float()
        z = predict_latents(model, data.motion(s))
        fit = fit_latents(model.decode, x, init=z)
        with torch.no_grad():
            networks, best = model.decode(z), model.decode(fit)
        out.append(
            NetworkFloor(
                source=data.sources[s],
                split=data.splits[s],
                frames=frames.stop - frames.start,
                decoder_fit_mm=1e3 * float((best - x).norm(dim=-1).mean()),
                networks_mm=1e3 * float((networks - x).norm(dim=-1).mean()),
            )
        )
        if progress is not None:
            progress(done)
    return out


def pose_canonical(
    model: GarmentModel, x: np.ndarray, betas: np.ndarray, pose: np.ndarray, trans: np.ndarray
) -> np.ndarray:
    """M_G(X, β, θ) + trans of canonical garments ``x`` ``(T, N, 3)`` (m) with one shape
    ``betas`` ``(10,)``, ``pose`` ``(T, 24, 3)`` (rad) and ``trans`` ``(T, 3)`` (m): the posed
    garments ``(T, N, 3)`` float32 (m), the fields looked up at every X."""
    b = torch.as_tensor(betas, dtype=torch.float32)
    out = np.empty(np.shape(x), dtype=np.float32)
    with torch.no_grad():
        for s in range(0, len(x), POSE_FRAMES):
            e = min(s + POSE_FRAMES, len(x))
            art = model.articulation(
                b, torch.as_tensor(pose[s:e]).float(), torch.as_tensor(trans[s:e]).float()
            )
            out[s:e] = model.pose(torch.as_tensor(x[s:e]).float(), art).vertices.numpy()
    return out


def representation_floor(
    data: CanonicalSet,
    body: BodyModel,
    fields: BodyFields,
    splits: Sequence[str] | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[SequenceFloor]:
    """The simulated and the posed-back figures of each sequence of ``data`` in ``splits`` (all
    by default), the simulations read from the set's sources.

    Args:
        progress: called with the number of sequences done.

    Raises:
        FileNotFoundError, UsdInputError: a source layer is missing or unreadable.
        ValueError: a source layer does not hold the set's frames of that sequence.
    """
    model = GarmentModel(body, fields)
    faces = body.faces.numpy()
    out = []
    for done, s in enumerate(_chosen(data, splits), 1):
        frames = data.sequence(s)
        simulated, _, _ = read_garment_layer(data.sources[s])
        if simulated.shape != data.canonical[frames].shape:
            raise ValueError(
                f"{data.sources[s]}: holds {simulated.shape[0]} frames of "
                f"{simulated.shape[1]} vertices, the set {data.canonical[frames].shape[:2]}"
            )
        pose, trans = data.pose[frames], data.trans[frames]
        with torch.no_grad():
            posed_body = body(
                torch.as_tensor(data.betas[s]).float(),
                torch.as_tensor(pose).float(),
                torch.as_tensor(trans).float(),
            ).vertices.numpy()
        reposed = pose_canonical(model, data.canonical[frames], data.betas[s], pose, trans)
        fps = float(data.fps[s])
        sim = evaluate_garment(simulated, posed_body, faces, fps)
        back = evaluate_garment(reposed, posed_body, faces, fps, reference=simulated)
        out.append(
            SequenceFloor(
                source=data.sources[s],
                split=data.splits[s],
                frames=frames.stop - frames.start,
                reprojection_mm=float(np.mean(back.reference_mm)),
                simulation=sim.summary(),
                reposed=back.summary(),
            )
        )
        if progress is not None:
            progress(done)
    return out
