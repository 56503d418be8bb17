"""Training the pose codec (the learned 10-d pose code of the motion descriptor): an autoencoder
of SMPL poses fitted by the mean squared error of the 207 pose features (R − I of joints 1..23),
each joint's error optionally weighted by how much of the garment it moves
(:func:`garment_joint_weights`), with per-epoch validation on a held-out share of the poses,
checkpoints and resume."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment.body.joints import NUM_JOINTS, SMPL_PARENTS
from usd_garment.motion.pose_corpus import PoseCorpus
from usd_garment.regressor.pose_code import PoseCodec, features_to_rotations, pose_to_features
from usd_garment.training.checkpoint import resume_checkpoint, save_checkpoint
from usd_garment.training.finite import require_finite

#: ``progress(epoch, total, row)``: called after each epoch (1-based) with its history row.
EpochProgress = Callable[[int, int, dict[str, Any]], None]
#: Tag of a pose codec checkpoint file.
CHECKPOINT_FORMAT = "usd_garment.pose_codec_checkpoint"
#: Poses evaluated at once in validation.
_EVAL_CHUNK = 4096


#: The default weight of a joint that moves none of the garment, against 1 for the one that
#: moves most (``PoseCodecTrainConfig.joint_weight_floor``).
WEIGHT_FLOOR = 0.1


@dataclass
class PoseCodecTrainConfig:
    """Settings of a pose codec training.

    Attributes:
        hidden: width of the encoder's and decoder's hidden layer (500 in the paper's code).
        code_size: entries of the pose code (10 in the paper).
        epochs: passes over the training poses.
        batch_size: poses per optimiser step.
        lr: Adam learning rate of the first epoch ...
        lr_decay: ... multiplied by this after every epoch.
        validation_fraction: share of the poses held out for validation (none if 0 or if fewer
            than 2 poses).
        joint_weighting: ``"uniform"`` (every joint's features alike, the paper's) or
            ``"garment"`` (each joint's squared error weighted by :func:`garment_joint_weights`
            of the training set's garment: the code spends itself on what moves the garment).
        joint_weight_floor: with ``"garment"``, the weight of a joint that moves none of the
            garment against 1 for the one that moves most (0: such joints are left out of the
            loss). Records written before this setting read back as 0.1, the floor they used.
        corpus: a pose corpus file (``usd-garment motion poses``) whose poses are trained on
            beside the training set's: real poses that no garment was simulated on (None: the
            training set's poses alone).
        seed: seed of the initial weights, the split and the shuffles.
        device: torch device of the training.
    """

    hidden: int = 500
    code_size: int = 10
    epochs: int = 100
    batch_size: int = 256
    lr: float = 1e-3
    lr_decay: float = 1.0
    validation_fraction: float = 0.1
    joint_weighting: str = "uniform"
    joint_weight_floor: float = WEIGHT_FLOOR
    corpus: str | None = None
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self) -> None:
        require_finite(self)
        if self.joint_weighting not in JOINT_WEIGHTINGS:
            raise ValueError(
                f"unknown joint_weighting '{self.joint_weighting}' ({', '.join(JOINT_WEIGHTINGS)})"
            )
        if not 0.0 <= self.joint_weight_floor <= 1.0:
            raise ValueError(f"joint_weight_floor must be in [0, 1], got {self.joint_weight_floor}")

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PoseCodecTrainConfig:
        """The config of ``asdict(config)`` or its JSON (unknown keys raise ``TypeError``)."""
        return cls(**values)


#: The values of ``PoseCodecTrainConfig.joint_weighting``.
JOINT_WEIGHTINGS = ("uniform", "garment")


def garment_joint_weights(skinning: torch.Tensor, floor: float = WEIGHT_FLOOR) -> torch.Tensor:
    """Weights ``(23,)`` of joints 1..23 in the pose codec's loss, from the garment's skinning
    weights ``(N, 24)`` (rows sum to 1) at its rest vertices.

    A joint's rotation moves every vertex skinned to it or to a joint below it in the tree, so
    its relevance is the share of the garment's skinning mass on its subtree. The weights are
    ``floor`` + (1 − ``floor``) × that share scaled to at most 1, then scaled to a mean of 1 (the
    loss keeps the size of the uniform one): a dress's hips and knees count, a T-shirt's barely.
    """
    mass = skinning.to(torch.float64).mean(0)  # (24,)
    subtree = mass.clone()
    for joint in range(NUM_JOINTS - 1, 0, -1):  # children come after their parents
        subtree[SMPL_PARENTS[joint]] += subtree[joint]
    share = subtree[1:] / subtree[1:].max().clamp(min=1e-12)
    weights = floor + (1.0 - floor) * share
    return (weights / weights.mean()).to(torch.float32)


@torch.no_grad()
def evaluate_pose_codec(codec: PoseCodec, poses: torch.Tensor | np.ndarray) -> dict[str, float]:
    """Reconstruction errors of ``codec`` on poses ``(M, 24, 3)`` (axis-angle, rad; root ignored).

    Returns:
        ``feature_mse``: mean squared error of the 207 pose features; ``angle_deg``: mean
        geodesic angle (degrees) between each joint's rotation (1..23) and its reconstruction
        (decoded features projected onto rotations).
    """
    device = next(codec.parameters()).device
    poses = torch.as_tensor(poses, dtype=torch.float32, device=device)
    sq, angle, count = 0.0, 0.0, 0
    for chunk in poses.split(_EVAL_CHUNK):
        features = pose_to_features(chunk)
        decoded = codec.decode(codec.encode_features(features))
        sq += float((decoded - features).square().mean(-1).sum())
        eye = torch.eye(3, dtype=features.dtype, device=device)
        target = features.reshape(-1, 23, 3, 3) + eye
        cos = ((features_to_rotations(decoded) * target).sum((-1, -2)) - 1.0) / 2.0
        angle += float(torch.rad2deg(torch.arccos(cos.clamp(-1.0, 1.0))).mean(-1).sum())
        count += chunk.shape[0]
    count = max(count, 1)
    return {"feature_mse": sq / count, "angle_deg": angle / count}


def corpus_errors(codec: PoseCodec, corpus: PoseCorpus) -> list[float]:
    """The mean geodesic angle (degrees) between each joint's rotation (1..23) and its
    reconstruction by ``codec`` (:func:`evaluate_pose_codec`) on each motion of ``corpus``, in
    the order of its sources."""
    bounds = np.cumsum([0, *corpus.counts])
    return [
        evaluate_pose_codec(codec, corpus.poses[a:b])["angle_deg"]
        for a, b in itertools.pairwise(bounds)
    ]


def train_pose_codec(
    poses: np.ndarray | torch.Tensor,
    config: PoseCodecTrainConfig | None = None,
    progress: EpochProgress | None = None,
    checkpoint: str | Path | None = None,
    resume: bool = False,
    joint_weights: torch.Tensor | None = None,
) -> tuple[PoseCodec, dict[str, Any]]:
    """Fit a :class:`PoseCodec` to poses.

    Args:
        poses: ``(M, 24, 3)`` local axis-angle rotations (rad), SMPL order; the root is ignored.
        config: training settings (defaults if None).
        joint_weights: ``(23,)`` weights of joints 1..23 in the training loss (None: all 1);
            needed when ``config.joint_weighting`` is ``"garment"``.
        progress: called after every epoch.
        checkpoint: file written after every epoch (``torch.save`` of the model, its config,
            the optimiser, the epoch, the history, the training config and the random state).
        resume: continue from ``checkpoint`` if that file exists (up to ``config.epochs``; the
            remaining epochs then match an uninterrupted run).

    Returns:
        The codec (in eval mode, on ``config.device``) and the history (JSON-able): ``config``,
        ``model``, ``train_poses``, ``validation_poses`` and ``epochs``, one row per epoch with
        ``epoch`` (1-based), ``lr``, ``train_mse`` (mean over the epoch's batches), ``val_mse``
        and ``val_angle_deg`` (when there is a validation share) and ``seconds``.

    The same data and config give the same result on the CPU (seeded weights and draws; the
    global torch random state is left alone); CUDA kernels may not be bitwise deterministic.

    Raises:
        ValueError: bad poses, or a checkpoint of another kind or model shape.
    """
    config = config or PoseCodecTrainConfig()
    if (joint_weights is None) != (config.joint_weighting == "uniform"):
        raise ValueError(f"joint_weighting '{config.joint_weighting}' with joint_weights "
                         f"{'missing' if joint_weights is None else 'given'}")  # fmt: skip
    poses = torch.as_tensor(np.asarray(poses), dtype=torch.float32)
    if poses.ndim != 3 or poses.shape[1:] != (24, 3) or poses.shape[0] == 0:
        raise ValueError(f"poses must be (M, 24, 3) with M > 0, got {tuple(poses.shape)}")
    device = torch.device(config.device)
    generator = torch.Generator().manual_seed(config.seed)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        codec = PoseCodec(config.hidden, config.code_size)
    codec.to(device)
    optimizer = torch.optim.Adam(codec.parameters(), lr=config.lr)

    m = poses.shape[0]
    order = torch.randperm(m, generator=generator)
    n_val = math.ceil(config.validation_fraction * m) if m >= 2 else 0
    n_val = min(n_val, m - 1)
    val_poses = poses[order[:n_val]]
    train_features = pose_to_features(poses[order[n_val:]]).to(device)
    weights = torch.ones(NUM_JOINTS - 1) if joint_weights is None else joint_weights.float()
    feature_weights = weights.repeat_interleave(9).to(device)  # (207,): 9 features per joint

    history: dict[str, Any] = {
        "config": asdict(config),
        "model": codec.config(),
        "train_poses": int(train_features.shape[0]),
        "validation_poses": int(n_val),
        "joint_weights": [round(float(w), 4) for w in weights],
        "epochs": [],
    }
    start = 0
    path = Path(checkpoint) if checkpoint is not None else None
    if resume and path is not None and path.is_file():
        state = resume_checkpoint(path, CHECKPOINT_FORMAT, codec, optimizer, generator, device)
        start = state["epoch"]
        history["epochs"] = list(state["history"]["epochs"])

    n = train_features.shape[0]
    for epoch in range(start, config.epochs):
        tic = time.perf_counter()
        lr = config.lr * config.lr_decay**epoch
        for group in optimizer.param_groups:
            group["lr"] = lr
        codec.train()
        perm = torch.randperm(n, generator=generator).to(device)
        total, batches = 0.0, 0
        for idx in perm.split(config.batch_size):
            features = train_features[idx]
            error = codec.decode(codec.encode_features(features)) - features
            loss = (error.square() * feature_weights).mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += float(loss.detach())
            batches += 1
        codec.eval()
        row: dict[str, Any] = {"epoch": epoch + 1, "lr": lr, "train_mse": total / max(batches, 1)}
        if n_val:
            errors = evaluate_pose_codec(codec, val_poses)
            row["val_mse"] = errors["feature_mse"]
            row["val_angle_deg"] = errors["angle_deg"]
        row["seconds"] = time.perf_counter() - tic
        history["epochs"].append(row)
        if path is not None:
            save_checkpoint(
                path, CHECKPOINT_FORMAT, codec, optimizer, generator, epoch + 1, history,
                asdict(config),
            )  # fmt: skip
        if progress is not None:
            progress(epoch + 1, config.epochs, row)
    codec.eval()
    return codec, history
