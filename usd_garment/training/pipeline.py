"""The training commands' work: the pose codec, the garment VAE and the regressor trained one
after another from a canonical training set into one model directory.

A run folder holds, beside the model files of :mod:`usd_garment.methods.learned_model`:
``checkpoints/{stage}.pt`` (resumable, per epoch), ``{stage}.json`` (the trained stage: its
configuration, history and network), ``train.log`` (one plain-text line per epoch) and
``config.json`` (every stage's settings). A stage that needs an earlier one reads it from the
same folder, so ``train pose``, ``train vae`` and ``train regressor`` run one by one give what
``train all`` gives.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment.atomic import atomic_output
from usd_garment.body.fingerprint import model_fingerprint
from usd_garment.body.model import BodyModel
from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.eval.machine import describe_machine
from usd_garment.fields.body_fields import BodyFields
from usd_garment.generative.vae import GarmentVAE
from usd_garment.methods.learned_model import (
    LOG_NAME,
    PARTS,
    LearnedModel,
    Member,
    load_learned_model,
    save_learned_model,
)
from usd_garment.motion.pose_corpus import load_pose_corpus
from usd_garment.regressor.gru import GarmentRegressor
from usd_garment.regressor.pose_code import PoseCodec
from usd_garment.training.pose import (
    PoseCodecTrainConfig,
    garment_joint_weights,
    train_pose_codec,
)
from usd_garment.training.posed_planes import PosedPlanes
from usd_garment.training.regressor import RegressorTrainConfig, train_regressor
from usd_garment.training.vae import VaeTrainConfig, split_frames, train_vae

#: The stages, in the order ``all`` runs them, and the network each trains.
STAGES = ("pose", "vae", "regressor")
STAGE_PART = {"pose": "pose_codec", "vae": "vae", "regressor": "regressor"}
#: The paper's two ablations of the VAE's collision loss.
ABLATIONS = ("none", "no-collision", "no-self-supervision")
#: Called after every epoch: ``(stage, epoch, epochs, history_row)``.
StageProgress = Callable[[str, int, int, dict[str, Any]], None]


@dataclass
class TrainSettings:
    """Settings of every stage of a run (stored as ``config.json``).

    Attributes:
        pose, vae, regressor: the stages' own settings.
        ablation: "none", or one of the paper's ablations of the VAE ("no-collision",
            "no-self-supervision").
        version: the trained model's version.
    """

    pose: PoseCodecTrainConfig = field(default_factory=PoseCodecTrainConfig)
    vae: VaeTrainConfig = field(default_factory=VaeTrainConfig)
    regressor: RegressorTrainConfig = field(default_factory=RegressorTrainConfig)
    ablation: str = "none"
    version: str = "1"

    def __post_init__(self) -> None:
        if self.ablation not in ABLATIONS:
            raise ValueError(f"unknown ablation '{self.ablation}' ({', '.join(ABLATIONS)})")
        if self.ablation == "no-collision":
            self.vae.collision = False
        elif self.ablation == "no-self-supervision":
            self.vae.self_supervised = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "pose": asdict(self.pose),
            "vae": self.vae.to_dict(),
            "regressor": asdict(self.regressor),
            "ablation": self.ablation,
            "version": self.version,
        }

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TrainSettings:
        """Inverse of ``to_dict``; missing stages take their defaults."""
        return cls(
            pose=PoseCodecTrainConfig.from_dict(values.get("pose", {})),
            vae=VaeTrainConfig.from_dict(values.get("vae", {})),
            regressor=RegressorTrainConfig.from_dict(values.get("regressor", {})),
            ablation=values.get("ablation", "none"),
            version=str(values.get("version", "1")),
        )

    def set_device(self, device: str) -> None:
        self.pose.device = self.vae.device = self.regressor.device = device


def _train_poses(data: CanonicalSet, config: PoseCodecTrainConfig) -> tuple[np.ndarray, int]:
    """``(M, 24, 3)`` poses of the ``train`` split's frames, then those of ``config.corpus``
    (when set), and how many came from the corpus."""
    poses = np.asarray(data.pose[split_frames(data, "train")], dtype=np.float32)
    if config.corpus is None:
        return poses, 0
    corpus = load_pose_corpus(config.corpus).poses
    return np.concatenate([poses, corpus]), len(corpus)


def _stage_file(folder: Path, stage: str) -> Path:
    return folder / f"{stage}.json"


def _weights_file(folder: Path, stage: str) -> Path:
    return folder / "checkpoints" / f"{stage}.final.pt"


def _save_stage(folder: Path, stage: str, net: torch.nn.Module, record: dict[str, Any]) -> None:
    """The trained network of ``stage`` (``checkpoints/{stage}.final.pt``) and its record."""
    with atomic_output(_weights_file(folder, stage)) as tmp:
        torch.save({k: v.detach().cpu() for k, v in net.state_dict().items()}, tmp)
    with atomic_output(_stage_file(folder, stage)) as tmp:
        tmp.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")


def load_stage(folder: str | Path, stage: str) -> tuple[torch.nn.Module, dict[str, Any]]:
    """The trained network of ``stage`` in the run ``folder`` and its record.

    Raises:
        FileNotFoundError: that stage has not been trained there.
    """
    folder = Path(folder)
    record_path, weights = _stage_file(folder, stage), _weights_file(folder, stage)
    if not record_path.is_file() or not weights.is_file():
        raise FileNotFoundError(f"{folder}: no trained '{stage}' stage (train it first)")
    record = json.loads(record_path.read_text(encoding="utf-8"))
    net = PARTS[STAGE_PART[stage]].from_config(record["architecture"])
    net.load_state_dict(torch.load(weights, map_location="cpu", weights_only=True))
    return net.eval(), record


def trained_pose_codecs(folder: str | Path) -> list[PoseCodec]:
    """The pose codes of a run folder (its trained pose stage) or, where it has none, of a
    model directory (each member's, in order).

    Raises:
        ModelError: neither (see :func:`load_learned_model`).
    """
    if _stage_file(Path(folder), "pose").is_file():
        codec = load_stage(folder, "pose")[0]
        assert isinstance(codec, PoseCodec)
        return [codec]
    return [member.pose_codec for member in load_learned_model(folder).members]


def _log(folder: Path, stage: str) -> Callable[[int, int, dict[str, Any]], None]:
    """An epoch callback appending one plain-text line per epoch to ``train.log``."""

    def write(epoch: int, total: int, row: dict[str, Any]) -> None:
        figures = " ".join(
            f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in row.items()
            if isinstance(v, (int, float)) and k != "epoch"
        )
        with open(folder / LOG_NAME, "a", encoding="utf-8") as log:
            log.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {stage} {epoch}/{total} {figures}\n")

    return write


def train_stage(
    stage: str,
    data: CanonicalSet,
    folder: str | Path,
    settings: TrainSettings,
    *,
    fields: BodyFields,
    planes: PosedPlanes | None = None,
    resume: bool = False,
    progress: StageProgress | None = None,
) -> dict[str, Any]:
    """Train one stage in the run ``folder`` (created) and save it there. ``planes``: the
    posed collision planes of ``data`` (:func:`posed_planes`), for a regressor trained with
    ``lambda_posed`` > 0. A regressor trained with ``tune_decoder`` saves the VAE stage again
    too, with its decoder as the training left it (its record gains ``tuned_with_regressor``).

    Returns:
        The stage's record: ``stage``, ``config``, ``architecture``, ``history``, ``seconds``
        (this run's wall time, plus the epochs' time of the runs it resumed) and
        ``resumed_epochs`` (the epochs that the resumed checkpoint held; 0 for a fresh run).

    Raises:
        FileNotFoundError: an earlier stage it needs is missing.
        ValueError: unknown stage, or a resume with other settings.
    """
    if stage not in STAGES:
        raise ValueError(f"unknown stage '{stage}' ({', '.join(STAGES)})")
    folder = Path(folder)
    (folder / "checkpoints").mkdir(parents=True, exist_ok=True)
    checkpoint = folder / "checkpoints" / f"{stage}.pt"
    log = _log(folder, stage)

    trained = []  # the epochs this run trains (a resume continues after the checkpoint's)

    def report(epoch: int, total: int, row: dict[str, Any]) -> None:
        trained.append(epoch)
        log(epoch, total, row)
        if progress is not None:
            progress(stage, epoch, total, row)

    started = time.perf_counter()
    net: torch.nn.Module
    if stage == "pose":
        config: Any = settings.pose
        weights = None
        if config.joint_weighting == "garment":
            template = torch.as_tensor(data.template, dtype=torch.float32)
            weights = garment_joint_weights(fields.weights(template), config.joint_weight_floor)
        poses, from_corpus = _train_poses(data, config)
        net, history = train_pose_codec(
            poses, config, report, checkpoint=checkpoint, resume=resume, joint_weights=weights
        )
        history["corpus_poses"] = from_corpus
    elif stage == "vae":
        config = settings.vae
        net, history = train_vae(
            data, config, fields=fields, progress=report, checkpoint=checkpoint, resume=resume
        )
    else:
        config = settings.regressor
        codec, _ = load_stage(folder, "pose")
        vae, vae_record = load_stage(folder, "vae")
        assert isinstance(vae, GarmentVAE) and isinstance(codec, PoseCodec)
        vae = vae.to(config.device).requires_grad_(config.tune_decoder)
        initial = None
        if config.init_from is not None:
            initial, _ = load_stage(config.init_from, "regressor")
            assert isinstance(initial, GarmentRegressor)
        net, history = train_regressor(
            data,
            lambda x: vae.encode(x)[0],
            codec.to(config.device),
            config,
            decode=vae.decode,
            planes=planes,
            initial=initial,
            decoder=vae.decoder,
            progress=report,
            checkpoint=checkpoint,
            resume=resume,
        )
        if config.tune_decoder:  # the decoder moved with the regressor: its stage is this one's
            vae_record["tuned_with_regressor"] = asdict(config)
            _save_stage(folder, "vae", vae.cpu(), vae_record)
    net = net.cpu()
    earlier = history["epochs"][: len(history["epochs"]) - len(trained)]
    record = {
        "stage": stage,
        "config": config.to_dict() if hasattr(config, "to_dict") else asdict(config),
        "architecture": net.config(),
        "history": history,
        "seconds": time.perf_counter() - started + sum(row["seconds"] for row in earlier),
        "resumed_epochs": len(earlier),
    }
    _save_stage(folder, stage, net, record)
    return record


def assemble_model(
    folder: str | Path,
    data: CanonicalSet,
    body: BodyModel,
    settings: TrainSettings,
    info: dict[str, Any] | None = None,
) -> LearnedModel:
    """Write the model files of the run ``folder`` from its trained stages.

    Args:
        info: extra ``model.json`` entries (the command that trained it, held-out figures).

    Raises:
        FileNotFoundError: a stage is missing.
    """
    folder = Path(folder)
    nets, records = {}, {}
    for stage in STAGES:
        nets[STAGE_PART[stage]], records[stage] = load_stage(folder, stage)
    vae, codec, regressor = nets["vae"], nets["pose_codec"], nets["regressor"]
    assert isinstance(vae, GarmentVAE) and isinstance(codec, PoseCodec)
    assert isinstance(regressor, GarmentRegressor)
    meta = data.metadata
    model = LearnedModel(
        # The encoder is for training: its weights stay in checkpoints/.
        [Member(vae=vae.decoder_only(), pose_codec=codec, regressor=regressor)],
        garment=str(meta.get("garment", "tshirt")),
        lod=str(meta.get("lod", "high")),
        vertices=int(data.template.shape[0]),
        version=settings.version,
        body_name=body.name,
        body_fingerprint=model_fingerprint(body),
        info={
            "ablation": settings.ablation,
            "training": {
                "settings": settings.to_dict(),
                "seconds": {stage: records[stage]["seconds"] for stage in STAGES},
                "machine": describe_machine(),
                "torch": torch.__version__,
                "data": {
                    "sequences": data.num_sequences,
                    "frames": {
                        split: len(split_frames(data, split))
                        for split in ("train", "validation", "test")
                    },
                    "metadata": meta,
                },
                "final": {stage: records[stage]["history"]["epochs"][-1:] for stage in STAGES},
            },
            **(info or {}),
        },
    )
    save_learned_model(folder, model)
    return model
