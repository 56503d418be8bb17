"""Training the recurrent garment regressor R(β, γ) of the paper's section 4 on a canonical
training set: the targets are the latent codes z of the canonical garments (the VAE encoder's
mean, given by the caller), the inputs the motion descriptor γ of each sequence at the model's
30 fps and its body shape β; the loss is L_pos + ρ1·L_vel + ρ2·L_acc, L1 on z and on its
per-frame first and second differences, over random crops of the training sequences; optionally
plus λ_posed·L_posed, the decoded garments held out of the posed body by the training targets'
collision planes pulled back to canonical space (:mod:`usd_garment.training.posed_planes`)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.generative.losses import COLLISION_EPSILON
from usd_garment.motion.resample import resample_motion
from usd_garment.regressor.descriptor import MODEL_FPS, descriptor_size, motion_descriptor
from usd_garment.regressor.gru import GarmentRegressor
from usd_garment.regressor.pose_code import PoseCodec
from usd_garment.training.checkpoint import resume_checkpoint, save_checkpoint
from usd_garment.training.finite import require_finite
from usd_garment.training.posed_planes import PosedPlanes

#: ``progress(epoch, total, row)``: called after each epoch (1-based) with its history row.
EpochProgress = Callable[[int, int, dict[str, Any]], None]
#: ``encode_latent(X (B, N, 3)) -> z (B, latent)``: the VAE encoder's mean of canonical garments.
EncodeLatent = Callable[[torch.Tensor], torch.Tensor]
#: ``decode(z (T, latent)) -> X (T, N, 3)``: the VAE decoder, canonical garments in metres.
DecodeLatent = Callable[[torch.Tensor], torch.Tensor]
#: Tag of a regressor checkpoint file.
CHECKPOINT_FORMAT = "usd_garment.regressor_checkpoint"


@dataclass
class RegressorTrainConfig:
    """Settings of a regressor training.

    Attributes:
        hidden: sizes of the GRU layers (500, 500 in the paper's code).
        crop_length: frames (at 30 fps) of each training crop; shorter sequences are used whole,
            padded and masked.
        batch_size: crops per optimiser step.
        crops_per_epoch: crops drawn per epoch; None: as many as fill the training frames once
            (total frames / crop_length, at least one batch).
        epochs: training epochs.
        lr: Adam learning rate of the first epoch ...
        lr_decay: ... multiplied by this after every epoch.
        rho1: weight ρ1 of L_vel (L1 of per-frame first differences of z).
        rho2: weight ρ2 of L_acc (L1 of per-frame second differences of z).
        grad_clip: largest gradient norm (None: no clipping).
        padding: first frames' derivatives in γ (``"repeat"`` or ``"zeros"``).
        weight_decay: decoupled weight decay of Adam (AdamW's; 0: none), per unit learning rate.
        input_noise: deviation of Gaussian noise added to each training crop's γ, in units of
            each entry's deviation over the training frames (0: none).
        encode_batch: frames per call of ``encode_latent`` and ``decode``.
        lambda_posed: weight of L_posed (per m): Σ_i max(ε − d_i, 0) of each decoded frame's
            vertices against its target's posed collision planes (ε = 2 mm; averaged over the
            crops' frames); 0: none. Needs the planes and the decoder.
        init_from: a run folder whose trained regressor (same architecture) starts the
            training, its input and output normalisation kept (fine-tuning); None: random
            initial weights.
        tune_decoder: train the VAE's decoder with the regressor (end to end, meant for
            fine-tuning): the loss gets λ_vertex·L_vertex, the mean distance (m) of the decoded
            crop frames' vertices to their canonical targets. Needs the decoder module; no
            ``resume``.
        lambda_vertex: λ_vertex (per m), with ``tune_decoder``.
        skip_flagged_frames: leave the frames that the simulation flagged (kept though they
            failed its checks) out of every training loss term and z's normalisation (at the
            model's frame rate, a frame interpolated from a flagged one is left out too); the
            crops still run the GRU through them (their body motion is sound), and γ's
            normalisation and the validation figures use all frames.
        seed: seed of the initial weights and of the crops.
        device: torch device of the training (``encode_latent``/``decode`` get tensors there).
    """

    hidden: tuple[int, ...] = (500, 500)
    crop_length: int = 90
    batch_size: int = 16
    crops_per_epoch: int | None = None
    epochs: int = 100
    lr: float = 1e-3
    lr_decay: float = 1.0
    rho1: float = 1.0
    rho2: float = 1.0
    grad_clip: float | None = 1.0
    padding: str = "repeat"
    weight_decay: float = 0.0
    input_noise: float = 0.0
    encode_batch: int = 256
    lambda_posed: float = 0.0
    init_from: str | None = None
    tune_decoder: bool = False
    lambda_vertex: float = 40.0
    skip_flagged_frames: bool = False
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self) -> None:
        require_finite(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> RegressorTrainConfig:
        """The config of ``asdict(config)`` or its JSON (unknown keys raise ``TypeError``)."""
        values = dict(values)
        if "hidden" in values:
            values["hidden"] = tuple(int(h) for h in values["hidden"])
        return cls(**values)


@dataclass
class RegressorSequence:
    """One training or validation sequence at the model's frame rate.

    Attributes:
        gamma: ``(T, 42)`` motion descriptor.
        betas: ``(10,)`` body shape.
        latent: ``(T, latent)`` target latent codes z.
        canonical: ``(T, N, 3)`` canonical garments (m), kept for validation sequences only.
        first_frame: the index of its first frame in the canonical set; None when it was
            resampled (its frames are not the set's).
        trusted: ``(T,)`` float, 1 where the frame's target enters the training losses, 0 where
            the simulation flagged it; None: every frame.
    """

    gamma: torch.Tensor
    betas: torch.Tensor
    latent: torch.Tensor
    canonical: torch.Tensor | None = None
    first_frame: int | None = None
    trusted: torch.Tensor | None = None

    @property
    def num_frames(self) -> int:
        return int(self.gamma.shape[0])


def resample_frames(values: np.ndarray, fps: float, target_fps: float) -> np.ndarray:
    """Per-frame arrays ``(T, ...)`` linearly interpolated at the frames ``resample_motion``
    gives for a motion of ``T`` frames at ``fps`` resampled to ``target_fps``."""
    t = values.shape[0]
    if t == 1 or np.isclose(fps, target_fps):
        return values
    duration = (t - 1) / fps
    count = int(np.floor(duration * target_fps + 1e-6)) + 1
    u = np.arange(count) / target_fps * fps
    i0 = np.minimum(np.floor(u).astype(int), t - 2)
    alpha = (u - i0).reshape(-1, *([1] * (values.ndim - 1)))
    out = (1.0 - alpha) * values[i0] + alpha * values[i0 + 1]
    return out.astype(values.dtype)


@torch.no_grad()
def prepare_sequence(
    data: CanonicalSet,
    s: int,
    encode_latent: EncodeLatent,
    codec: PoseCodec,
    config: RegressorTrainConfig,
    keep_canonical: bool = False,
) -> RegressorSequence:
    """γ, β and latent targets of sequence ``s`` of ``data``, resampled to :data:`MODEL_FPS`
    (pose by slerp, translation and canonical garments linearly) if its fps differs; with
    ``config.skip_flagged_frames``, which frames are trusted (a resampled frame is not when either
    frame it is interpolated from was flagged).

    Raises:
        ValueError: ``skip_flagged_frames`` on a set without a record of flagged frames.
    """
    device = torch.device(config.device)
    frames = data.sequence(s)
    fps = float(data.fps[s])
    motion = resample_motion(data.motion(s), MODEL_FPS)
    canonical = resample_frames(
        np.asarray(data.canonical[frames], dtype=np.float32), fps, MODEL_FPS
    )
    gamma = motion_descriptor(motion.pose, motion.trans, codec, MODEL_FPS, config.padding)
    trusted = None
    if config.skip_flagged_frames:
        flagged = resample_frames(data.flags()[frames].astype(np.float32), fps, MODEL_FPS) > 0
        trusted = torch.as_tensor(~flagged, dtype=torch.float32, device=device)
    x = torch.as_tensor(canonical, dtype=torch.float32)
    latent = torch.cat(
        [
            torch.as_tensor(encode_latent(chunk.to(device))).to(device, torch.float32)
            for chunk in x.split(max(1, config.encode_batch))
        ]
    )
    return RegressorSequence(
        gamma=gamma.to(device),
        betas=torch.as_tensor(motion.betas, device=device),
        latent=latent,
        canonical=x if keep_canonical else None,
        first_frame=frames.start if np.isclose(fps, MODEL_FPS) else None,
        trusted=trusted,
    )


def latent_losses(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The paper's L_pos, L_vel and L_acc: mean absolute error of z ``(B, T, D)``, of its
    per-frame first differences and of its second differences (differences in latent units per
    frame, not per second), over the frames ``mask (B, T)`` marks valid (all if None)."""
    if mask is None:
        mask = pred.new_ones(pred.shape[:2])
    mask = mask.to(pred.dtype)
    d = pred.shape[-1]

    def _l1(a: torch.Tensor, b: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
        return ((a - b).abs().sum(-1) * m).sum() / (m.sum() * d).clamp_min(1.0)

    err_pos = _l1(pred, target, mask)
    dp, dt = pred[:, 1:] - pred[:, :-1], target[:, 1:] - target[:, :-1]
    mv = mask[:, 1:] * mask[:, :-1]
    err_vel = _l1(dp, dt, mv)
    ma = mv[:, 1:] * mv[:, :-1]
    err_acc = _l1(dp[:, 1:] - dp[:, :-1], dt[:, 1:] - dt[:, :-1], ma)
    return err_pos, err_vel, err_acc


def _normalization(
    sequences: list[RegressorSequence],
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Mean and deviation of ``[γ, β]`` per frame over the training frames and of z over the
    trusted ones."""
    inputs = torch.cat(
        [torch.cat([q.gamma, q.betas.expand(q.num_frames, -1)], dim=-1) for q in sequences]
    ).double()
    latent = torch.cat(
        [q.latent if q.trusted is None else q.latent[q.trusted > 0] for q in sequences]
    ).double()
    return (
        inputs.mean(0).float(),
        inputs.std(0, correction=0).float(),
        latent.mean(0).float(),
        latent.std(0, correction=0).float(),
    )


def _batch(
    sequences: list[RegressorSequence],
    picks: list[tuple[int, int]],
    length: int,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Crops ``(B, L, ·)`` of γ and z, the betas ``(B, 10)`` and the mask ``(B, L)`` of the frames
    whose targets count (not padding, trusted)."""
    first = sequences[0]
    b = len(picks)
    gamma = first.gamma.new_zeros((b, length, first.gamma.shape[-1]))
    latent = first.latent.new_zeros((b, length, first.latent.shape[-1]))
    mask = first.gamma.new_zeros((b, length))
    betas = torch.stack([sequences[s].betas for s, _ in picks])
    for i, (s, start) in enumerate(picks):
        q = sequences[s]
        n = min(length, q.num_frames - start)
        gamma[i, :n] = q.gamma[start : start + n]
        latent[i, :n] = q.latent[start : start + n]
        mask[i, :n] = 1.0 if q.trusted is None else q.trusted[start : start + n]
    return gamma, betas, latent, mask


@torch.no_grad()
def evaluate_regressor(
    model: GarmentRegressor,
    sequences: list[RegressorSequence],
    decode: DecodeLatent | None = None,
    decode_batch: int = 256,
    planes: PosedPlanes | None = None,
) -> dict[str, float]:
    """Errors of ``model`` run from rest over each whole sequence.

    Returns:
        ``pos``, ``vel``, ``acc``: the latent L1 losses averaged over the sequences' frames
        (weighted by their frame counts); with ``decode`` and the sequences' canonical garments,
        ``vertex_mm``: mean distance (mm) between decoded predicted and true canonical vertices;
        with ``decode`` and ``planes`` too, ``posed_inside_pct``: the share (%) of the decoded
        vertices behind their posed collision plane (sequences at the set's frames).
    """
    sums = {"pos": 0.0, "vel": 0.0, "acc": 0.0}
    frames = 0
    vertex_sum, vertex_count = 0.0, 0
    behind, planed = 0, 0
    for q in sequences:
        pred = model.predict(q.gamma, q.betas)
        losses = latent_losses(pred[None], q.latent[None])
        for key, value in zip(sums, losses, strict=True):
            sums[key] += float(value) * q.num_frames
        frames += q.num_frames
        planed_here = planes is not None and q.first_frame is not None
        if decode is None or (q.canonical is None and not planed_here):
            continue
        for a in range(0, q.num_frames, decode_batch):
            b = min(a + decode_batch, q.num_frames)
            decoded = torch.as_tensor(decode(pred[a:b])).to("cpu", torch.float32)
            if q.canonical is not None:
                vertex_sum += float((decoded - q.canonical[a:b]).norm(dim=-1).sum())
                vertex_count += decoded.shape[0] * decoded.shape[1]
            if planed_here:
                assert planes is not None and q.first_frame is not None
                index = torch.arange(q.first_frame + a, q.first_frame + b)
                behind += int(planes.inside(index, decoded.to(planes.normal.device)).sum())
                planed += decoded.shape[0] * decoded.shape[1]
    out = {key: value / max(frames, 1) for key, value in sums.items()}
    if vertex_count:
        out["vertex_mm"] = 1000.0 * vertex_sum / vertex_count
    if planed:
        out["posed_inside_pct"] = 100.0 * behind / planed
    return out


def decoded_crops(
    pred: torch.Tensor,
    sequences: list[RegressorSequence],
    picks: list[tuple[int, int]],
    decode: DecodeLatent,
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The decoded garments ``(F, N, 3)`` (m) of the predicted codes ``pred`` ``(B, L, latent)``
    of the crops ``picks`` (sequence, first frame) of ``sequences``, and each one's frame index
    in the canonical set ``(F,)``; padding, untrusted frames and resampled sequences (whose
    frames are not the set's) are left out; None when nothing is left. Decoded once for
    L_posed and L_vertex."""
    rows, cols, frames = [], [], []
    for i, (s, start) in enumerate(picks):
        q = sequences[s]
        if q.first_frame is None:
            continue
        n = min(pred.shape[1], q.num_frames - start)
        col = torch.arange(n)
        if q.trusted is not None:
            col = col[q.trusted[start : start + n].cpu() > 0]
        rows.append(torch.full((len(col),), i))
        cols.append(col)
        frames.append(q.first_frame + start + col)
    if not rows or not sum(len(c) for c in cols):
        return None
    return decode(pred[torch.cat(rows), torch.cat(cols)]), torch.cat(frames)


def vertex_loss(x: torch.Tensor, frames: torch.Tensor, canonical: np.ndarray) -> torch.Tensor:
    """L_vertex: the mean distance (m) of decoded garments ``x`` ``(F, N, 3)`` to the canonical
    targets ``canonical`` ``(T, N, 3)`` of their frames ``frames`` ``(F,)`` (the set's)."""
    target = torch.as_tensor(np.asarray(canonical[frames.numpy()], dtype=np.float32))
    return (x - target.to(x.device)).norm(dim=-1).mean()


@torch.no_grad()
def _decoder_floor_mm(
    sequences: list[RegressorSequence], decode: DecodeLatent, decode_batch: int
) -> float:
    """Mean vertex distance (mm) of the decoded target latents to the true canonical garments:
    the error a perfect regressor would have."""
    total, count = 0.0, 0
    for q in sequences:
        assert q.canonical is not None
        for z, x in zip(q.latent.split(decode_batch), q.canonical.split(decode_batch), strict=True):
            decoded = torch.as_tensor(decode(z)).to("cpu", torch.float32)
            total += float((decoded - x).norm(dim=-1).sum())
            count += x.shape[0] * x.shape[1]
    return 1000.0 * total / max(count, 1)


def train_regressor(
    data: CanonicalSet,
    encode_latent: EncodeLatent,
    codec: PoseCodec,
    config: RegressorTrainConfig | None = None,
    *,
    decode: DecodeLatent | None = None,
    planes: PosedPlanes | None = None,
    initial: GarmentRegressor | None = None,
    decoder: torch.nn.Module | None = None,
    progress: EpochProgress | None = None,
    checkpoint: str | Path | None = None,
    resume: bool = False,
) -> tuple[GarmentRegressor, dict[str, Any]]:
    """Fit a :class:`GarmentRegressor` to the ``train`` sequences of a canonical training set.

    Args:
        data: the canonical training set (sequences with splits ``train`` and ``validation``).
        encode_latent: maps canonical garments ``(B, N, 3)`` (m, float32, on ``config.device``)
            to their latent codes ``(B, latent)``: the VAE encoder's mean. Called without grad.
        codec: the trained pose codec of γ.
        config: training settings (defaults if None).
        decode: the VAE decoder ``z (T, latent) -> X (T, N, 3)``; given, validation also reports
            the canonical vertex error in mm.
        planes: the posed collision planes of ``data``'s frames (:func:`posed_planes`); needed
            when ``config.lambda_posed`` > 0; given, validation also reports
            ``posed_inside_pct``.
        initial: the regressor whose weights and normalisation start the training (the one
            ``config.init_from`` names); None: seeded random weights, normalisation from the
            training frames.
        decoder: the module behind ``decode`` whose parameters train too with
            ``config.tune_decoder`` (it is changed in place).
        progress: called after every epoch.
        checkpoint: file written after every epoch (``torch.save`` of the model, its config,
            the optimiser, the epoch, the history, the training config and the random state).
        resume: continue from ``checkpoint`` if that file exists (up to ``config.epochs``; the
            remaining epochs then match an uninterrupted run).

    Returns:
        The regressor (eval mode, on ``config.device``, normalisation set from the training
        frames) and the history (JSON-able): ``config``, ``model``, ``codec``, the sequence and
        frame counts, ``flagged_frames_skipped`` (training frames at the model's rate),
        ``decoder_floor_mm`` (the validation vertex error of the true latents when
        ``decode`` is given) and ``epochs``, one row per epoch: ``epoch`` (1-based), ``lr``,
        ``train_loss``, ``train_pos``, ``train_vel``, ``train_acc`` (means over the epoch's
        batches; ``train_posed`` too with λ_posed > 0, ``train_vertex_mm`` with
        ``tune_decoder``), ``val_pos``, ``val_vel``, ``val_acc``,
        ``val_vertex_mm`` and ``val_posed_inside_pct`` (when there are validation sequences,
        and a decoder and planes for the last two), ``seconds``.

    The same data and config give the same result on the CPU (seeded weights and draws; the
    global torch random state is left alone); CUDA kernels may not be bitwise deterministic.

    Raises:
        ValueError: no training sequences, a bad config, ``skip_flagged_frames`` on a set without
            a record of flagged frames, or a checkpoint of another kind or model shape.
    """
    config = config or RegressorTrainConfig()
    if config.crop_length < 3 or config.batch_size < 1:
        raise ValueError("crop_length must be at least 3 and batch_size at least 1")
    if min(config.weight_decay, config.input_noise, config.lambda_posed, config.lambda_vertex) < 0:
        raise ValueError(
            "weight_decay, input_noise, lambda_posed and lambda_vertex must not be negative"
        )
    if config.lambda_posed > 0 and (planes is None or decode is None):
        raise ValueError("lambda_posed > 0 needs the posed collision planes and the decoder")
    if config.tune_decoder and (decoder is None or decode is None):
        raise ValueError("tune_decoder needs the decoder module and decode")
    if config.tune_decoder and resume:
        raise ValueError("a regressor trained with tune_decoder cannot be resumed")
    train_ids = data.split_sequences("train")
    if not train_ids:
        raise ValueError("the canonical set has no 'train' sequences")
    val_ids = data.split_sequences("validation")
    device = torch.device(config.device)
    codec = codec.to(device).eval()

    train = [prepare_sequence(data, s, encode_latent, codec, config) for s in train_ids]
    keep = decode is not None
    val = [prepare_sequence(data, s, encode_latent, codec, config, keep) for s in val_ids]
    latent_size = int(train[0].latent.shape[-1])

    generator = torch.Generator().manual_seed(config.seed)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        model = GarmentRegressor(
            descriptor_size(codec.code_size), config.hidden, latent_size, train[0].betas.numel()
        )
    if initial is not None:
        if initial.config() != model.config():
            raise ValueError(
                f"the initial regressor is {initial.config()}, the config asks for {model.config()}"
            )
        model.load_state_dict(initial.state_dict())
    else:
        model.set_normalization(*_normalization(train))
    model.to(device)
    parameters = list(model.parameters())
    if config.tune_decoder:
        assert decoder is not None
        parameters += list(decoder.parameters())
    optimizer = torch.optim.Adam(parameters, lr=config.lr)
    gamma_std = model.input_std[: descriptor_size(codec.code_size)]

    lengths = [q.num_frames for q in train]
    total_frames = sum(lengths)
    history: dict[str, Any] = {
        "config": asdict(config),
        "model": model.config(),
        "codec": codec.config(),
        "train_sequences": len(train),
        "train_frames": total_frames,
        "flagged_frames_skipped": sum(
            int((q.trusted == 0).sum()) for q in train if q.trusted is not None
        ),
        "validation_sequences": len(val),
        "validation_frames": sum(q.num_frames for q in val),
        "decoder_floor_mm": None,
        "epochs": [],
    }
    start = 0
    path = Path(checkpoint) if checkpoint is not None else None
    if resume and path is not None and path.is_file():
        state = resume_checkpoint(path, CHECKPOINT_FORMAT, model, optimizer, generator, device)
        start = state["epoch"]
        history["epochs"] = list(state["history"]["epochs"])
        history["decoder_floor_mm"] = state["history"].get("decoder_floor_mm")
    if decode is not None and val and history["decoder_floor_mm"] is None:
        history["decoder_floor_mm"] = _decoder_floor_mm(val, decode, config.encode_batch)

    length = config.crop_length
    # sequences drawn in proportion to their crop starts: every start is equally likely
    weights = torch.tensor([max(n - length + 1, 1) for n in lengths], dtype=torch.float64)
    crops = config.crops_per_epoch or max(total_frames // length, config.batch_size)
    steps = math.ceil(crops / config.batch_size)
    for epoch in range(start, config.epochs):
        tic = time.perf_counter()
        lr = config.lr * config.lr_decay**epoch
        for group in optimizer.param_groups:
            # set every epoch, before any step: a resumed optimizer's groups would otherwise
            # carry the checkpoint's values
            group.update(lr=lr, weight_decay=config.weight_decay, decoupled_weight_decay=True)
        model.train()
        sums = np.zeros(6)
        for step in range(steps):
            b = min(config.batch_size, crops - step * config.batch_size)
            seqs = torch.multinomial(weights, b, replacement=True, generator=generator).tolist()
            u = torch.rand(b, generator=generator, dtype=torch.float64).tolist()
            picks = [
                (s, int(ui * max(lengths[s] - length + 1, 1)))
                for s, ui in zip(seqs, u, strict=True)
            ]
            gamma, betas, target, mask = _batch(train, picks, length)
            if config.input_noise > 0:
                noise = torch.randn(gamma.shape, generator=generator).to(device)
                gamma = gamma + config.input_noise * gamma_std * noise
            pred, _ = model(gamma, betas)
            pos, vel, acc = latent_losses(pred, target, mask)
            loss = pos + config.rho1 * vel + config.rho2 * acc
            posed, vertex = pred.new_zeros(()), pred.new_zeros(())
            decoded = None
            if config.lambda_posed > 0 or config.tune_decoder:
                assert decode is not None
                decoded = decoded_crops(pred, train, picks, decode)
            if decoded is not None:
                x, frames = decoded
                if config.lambda_posed > 0:
                    assert planes is not None
                    posed = planes.loss(frames, x.to(planes.normal.device), COLLISION_EPSILON)
                    loss = loss + config.lambda_posed * posed
                if config.tune_decoder:
                    vertex = vertex_loss(x, frames, data.canonical)
                    loss = loss + config.lambda_vertex * vertex
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if config.grad_clip is not None:
                torch.nn.utils.clip_grad_norm_(parameters, config.grad_clip)
            optimizer.step()
            sums += [float(v.detach()) for v in (loss, pos, vel, acc, posed, vertex)]
        model.eval()
        sums /= max(steps, 1)
        row: dict[str, Any] = {
            "epoch": epoch + 1,
            "lr": lr,
            "train_loss": float(sums[0]),
            "train_pos": float(sums[1]),
            "train_vel": float(sums[2]),
            "train_acc": float(sums[3]),
        }
        if config.lambda_posed > 0:
            row["train_posed"] = float(sums[4])
        if config.tune_decoder:
            row["train_vertex_mm"] = 1000.0 * float(sums[5])
        if val:
            errors = evaluate_regressor(model, val, decode, config.encode_batch, planes)
            row.update({f"val_{key}": value for key, value in errors.items()})
        row["seconds"] = time.perf_counter() - tic
        history["epochs"].append(row)
        if path is not None:
            save_checkpoint(
                path, CHECKPOINT_FORMAT, model, optimizer, generator, epoch + 1, history,
                asdict(config),
            )  # fmt: skip
        if progress is not None:
            progress(epoch + 1, config.epochs, row)
    model.eval()
    return model, history
