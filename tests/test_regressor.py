"""The regressor of the paper's section 4: pose codec, motion descriptor γ, GRU regressor and
their trainings, on small synthetic data."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.motion.sequence import SmplMotion
from usd_garment.regressor import (
    MODEL_FPS,
    GarmentRegressor,
    PoseCodec,
    describe_motion,
    descriptor_layout,
    motion_descriptor,
)
from usd_garment.regressor.pose_code import pose_to_features
from usd_garment.training.pose import (
    PoseCodecTrainConfig,
    evaluate_pose_codec,
    garment_joint_weights,
    train_pose_codec,
)
from usd_garment.training.posed_planes import PosedPlanes
from usd_garment.training.regressor import (
    RegressorTrainConfig,
    decoded_crops,
    latent_losses,
    prepare_sequence,
    train_regressor,
)

torch.set_num_threads(1)


def _codec(seed: int = 0) -> PoseCodec:
    torch.manual_seed(seed)
    return PoseCodec(hidden=32, code_size=10).eval()


def smooth_poses(frames: int, seed: int, amplitude: float = 0.6) -> np.ndarray:
    """``(T, 24, 3)`` axis-angle poses (rad): per joint, sums of slow random sinusoids."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[:, None, None] / 30.0
    freq = rng.uniform(0.2, 1.5, (3, 24, 3))
    phase = rng.uniform(0, 2 * np.pi, (3, 24, 3))
    amp = rng.uniform(0.2, 1.0, (3, 24, 3)) * amplitude / 3
    return sum(amp[k] * np.sin(2 * np.pi * freq[k] * t + phase[k]) for k in range(3))


def wandering_motion(frames: int = 40, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Pose with a tilted, turning root and a curved root path: ``(T, 24, 3)``, ``(T, 3)``."""
    pose = smooth_poses(frames, seed)
    t = np.arange(frames) / 30.0
    root = Rotation.from_euler("y", (0.8 * t + 0.3)[:, None]) * Rotation.from_euler(
        "xz", np.stack([0.3 * np.sin(2 * t), 0.2 * np.cos(3 * t)], axis=1)
    )
    pose[:, 0] = root.as_rotvec()
    trans = np.stack([np.sin(t), 0.9 + 0.05 * np.sin(4 * t), 0.5 * t**2], axis=1)
    return pose, trans


# --- descriptor ---------------------------------------------------------------------------


def test_descriptor_shape_and_layout() -> None:
    pose, trans = wandering_motion(25)
    gamma = motion_descriptor(pose, trans, _codec())
    assert gamma.shape == (25, 42) and gamma.dtype == torch.float32
    assert torch.isfinite(gamma).all()
    layout = descriptor_layout()
    covered = sorted(i for s in layout.values() for i in range(42)[s])
    assert covered == list(range(42))
    # the pose code part is the codec's code; a single frame has zero derivatives
    codec = _codec()
    with torch.no_grad():
        code = codec.encode(torch.as_tensor(pose, dtype=torch.float32))
    torch.testing.assert_close(gamma[:, layout["code"]], code)
    one = motion_descriptor(pose[:1], trans[:1], codec)
    assert one.shape == (1, 42) and (one[:, 10:] == 0).all()


def test_descriptor_invariant_to_heading_and_offset() -> None:
    pose, trans = wandering_motion(40)
    codec = _codec()
    gamma = motion_descriptor(pose, trans, codec)
    for angle in (0.7, -2.5, math.pi):
        turn = Rotation.from_euler("y", angle)
        moved = pose.copy()
        moved[:, 0] = (turn * Rotation.from_rotvec(pose[:, 0])).as_rotvec()
        moved_trans = turn.apply(trans) + np.array([3.0, -0.2, -7.5])
        other = motion_descriptor(moved, moved_trans, codec)
        torch.testing.assert_close(other, gamma, rtol=1e-5, atol=1e-4)
    # ... but not to a tilt of the whole motion (the heading frame keeps gravity's direction)
    tilt = Rotation.from_euler("x", 0.5)
    tilted = pose.copy()
    tilted[:, 0] = (tilt * Rotation.from_rotvec(pose[:, 0])).as_rotvec()
    other = motion_descriptor(tilted, tilt.apply(trans), codec)
    assert (other[:, 30:] - gamma[:, 30:]).abs().max() > 0.1


def test_descriptor_values_of_simple_motions() -> None:
    """Walking forward at 1.2 m/s while turning at 0.5 rad/s about Y: the heading frame sees
    a constant forward velocity, the centripetal acceleration and a pure yaw rate."""
    frames, speed, yaw_rate = 30, 1.2, 0.5
    t = np.arange(frames) / MODEL_FPS
    heading = 0.4 + yaw_rate * t
    pose = np.zeros((frames, 24, 3))
    pose[:, 0] = Rotation.from_euler("y", heading[:, None]).as_rotvec()
    radius = speed / yaw_rate  # circle whose tangent is the body's forward +Z
    trans = np.stack(
        [radius * (1 - np.cos(heading)), np.zeros(frames), radius * np.sin(heading)], axis=1
    )
    gamma = motion_descriptor(pose, trans, _codec()).double()
    layout = descriptor_layout()
    vel = gamma[2:, layout["trans_vel"]]
    # backward difference of a chord: the mean direction lies half a step behind
    half = yaw_rate / MODEL_FPS / 2
    chord = speed * math.sin(half) / half
    expected = torch.tensor([-chord * math.sin(half), 0.0, chord * math.cos(half)]).double()
    torch.testing.assert_close(vel, expected.expand_as(vel), rtol=0, atol=1e-5)
    acc = gamma[2:, layout["trans_acc"]]
    assert torch.allclose(acc.norm(dim=-1), torch.full_like(acc[:, 0], speed * yaw_rate), atol=1e-3)
    assert (acc[:, 0] > 0).all()  # towards the centre: turning about +Y takes forward +Z to +X
    rot_vel = gamma[:, layout["rot_vel"]]
    expected_rot = torch.tensor([0.0, yaw_rate, 0.0]).double().expand_as(rot_vel)
    torch.testing.assert_close(rot_vel, expected_rot, rtol=0, atol=1e-5)
    torch.testing.assert_close(
        gamma[:, layout["rot_acc"]], torch.zeros_like(rot_vel), atol=1e-3, rtol=0
    )
    # first frames repeat the first defined derivative, or are zero with padding="zeros"
    assert torch.equal(gamma[0, layout["trans_vel"]], gamma[1, layout["trans_vel"]])
    zeros = motion_descriptor(pose, trans, _codec(), padding="zeros")
    assert (zeros[0, 10:] == 0).all() and (zeros[1, layout["trans_acc"]] == 0).all()
    torch.testing.assert_close(zeros[3:], gamma[3:].float())


def test_describe_motion_resamples_to_model_rate() -> None:
    pose, trans = wandering_motion(61)
    motion = SmplMotion(betas=np.zeros(10), pose=pose, trans=trans, fps=60.0)
    gamma, resampled = describe_motion(motion, _codec())
    assert resampled.fps == MODEL_FPS and gamma.shape == (31, 42)
    torch.testing.assert_close(
        gamma, motion_descriptor(pose[::2], trans[::2], _codec()), rtol=1e-5, atol=1e-4
    )
    with pytest.raises(ValueError):
        motion_descriptor(pose[:, :23], trans, _codec())
    with pytest.raises(ValueError):
        motion_descriptor(pose, trans, _codec(), padding="mirror")


def test_the_runs_between_cuts_are_described_on_their_own() -> None:
    """A root teleported 0.5 m (a cut, ``root_cuts``): γ of each run between cuts on its own,
    so the regressor never sees the jump as a velocity (15 m/s at 30 fps); at 25 frames/s the
    frame resampled between the cut and the frame before it is that frame, not a blend of the
    two sides, and the cut lands on the first 30 fps frame at or after it."""
    from usd_garment.motion.resample import resample_motion, resampled_cuts

    pose, trans = wandering_motion(50)
    trans[20:, 0] += 0.5
    motion = SmplMotion(betas=np.zeros(10), pose=pose, trans=trans, fps=MODEL_FPS)
    gamma, _ = describe_motion(motion, _codec())
    runs = [motion_descriptor(pose[a:b], trans[a:b], _codec()) for a, b in ((0, 20), (20, 50))]
    torch.testing.assert_close(gamma, torch.cat(runs))
    speed = gamma[:, descriptor_layout()["trans_vel"]].norm(dim=-1)
    assert float(speed.max()) < 3.0  # the path's own speed
    jumped = motion_descriptor(pose, trans, _codec())[:, descriptor_layout()["trans_vel"]]
    assert float(jumped.norm(dim=-1).max()) > 14.0
    slow = SmplMotion(betas=np.zeros(10), pose=pose, trans=trans, fps=25.0)
    resampled = resample_motion(slow, MODEL_FPS, (20,))
    assert resampled_cuts((20,), 25.0, MODEL_FPS, 59) == (24,)  # 20 / 25 s = 24 / 30 s
    # At 120 frames/s: a one-frame glitch (two cuts) between two frames at 30 is one cut there,
    # and a cut after the last frame at 30 none.
    assert resampled_cuts((5, 6, 49), 120.0, MODEL_FPS, 13) == (2,)
    np.testing.assert_array_equal(resampled.trans[23], trans[19])  # 23 / 30 s: 19.17 / 25
    np.testing.assert_allclose(resampled.trans[22], trans[18] + 1 / 3 * (trans[19] - trans[18]))
    blended = resample_motion(slow, MODEL_FPS).trans[23]
    assert 0.05 < blended[0] - trans[19, 0] < 0.5  # without the cut: partly across the jump
    glitch = SmplMotion(np.zeros(10), pose, trans.copy(), 120.0)
    glitch.trans[49, 1] += 0.5  # the last frame jumps
    glitch.trans[5, 1] += 0.5  # and one frame of the first few
    gamma, at_30 = describe_motion(glitch, _codec())
    assert at_30.num_frames == 13 and torch.isfinite(gamma).all()


# --- GRU regressor ------------------------------------------------------------------------


def test_gru_streaming_equals_whole_sequence() -> None:
    torch.manual_seed(0)
    model = GarmentRegressor(42, hidden=(16, 12), latent_size=25).eval()
    model.set_normalization(torch.rand(52), torch.rand(52) + 0.5, torch.rand(25), torch.rand(25))
    gamma, betas = torch.randn(2, 23, 42), torch.randn(2, 10)
    with torch.no_grad():
        whole, state = model(gamma, betas)
        parts, chunk_state = [], None
        for chunk in gamma.split([5, 1, 10, 7], dim=1):
            z, chunk_state = model(chunk, betas, chunk_state)
            parts.append(z)
    assert whole.shape == (2, 23, 25)
    torch.testing.assert_close(torch.cat(parts, dim=1), whole, rtol=1e-5, atol=1e-6)
    for a, b in zip(state, chunk_state, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(model.predict(gamma[1], betas[1], chunk=4), whole[1])


def test_gru_starts_from_rest_at_each_restart() -> None:
    """With restarts, each run between them gets the codes it gets alone (the GRU from rest, as
    at a training crop's first frame), chunked or not; without them the state runs on."""
    torch.manual_seed(0)
    model = GarmentRegressor(42, hidden=(16, 12), latent_size=25).eval()
    gamma, betas = torch.randn(30, 42), torch.randn(10)
    cut = model.predict(gamma, betas, chunk=4, restarts=(9, 20))
    alone = [model.predict(gamma[a:b], betas) for a, b in ((0, 9), (9, 20), (20, 30))]
    torch.testing.assert_close(cut, torch.cat(alone), rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(model.predict(gamma, betas, restarts=(9, 20)), cut)
    across = model.predict(gamma, betas)
    torch.testing.assert_close(across[:9], cut[:9])
    assert (across[9] - cut[9]).abs().max() > 1e-3


def test_configs_round_trip() -> None:
    codec = PoseCodec(hidden=48, code_size=7)
    again = PoseCodec.from_config(json.loads(json.dumps(codec.config())))
    assert again.config() == codec.config()
    again.load_state_dict(codec.state_dict())
    poses = torch.as_tensor(smooth_poses(4, 1), dtype=torch.float32)
    torch.testing.assert_close(again.encode(poses), codec.encode(poses))

    model = GarmentRegressor(33, hidden=(20, 10, 8), latent_size=5)
    model.set_normalization(torch.ones(43) * 2, torch.ones(43) * 3, torch.ones(5), torch.ones(5))
    rebuilt = GarmentRegressor.from_config(json.loads(json.dumps(model.config())))
    assert rebuilt.config() == model.config()
    rebuilt.load_state_dict(model.state_dict())  # normalisation buffers come along
    assert torch.equal(rebuilt.input_std, model.input_std)

    train = RegressorTrainConfig(hidden=(64, 32), rho1=0.5, crops_per_epoch=7)
    assert RegressorTrainConfig.from_dict(json.loads(json.dumps(asdict(train)))) == train
    pose_cfg = PoseCodecTrainConfig(hidden=12, epochs=3)
    assert PoseCodecTrainConfig.from_dict(json.loads(json.dumps(asdict(pose_cfg)))) == pose_cfg


def test_latent_losses_masking() -> None:
    target = torch.randn(2, 6, 3)
    pred = target.clone()
    pred[1, 4:] += 5.0  # error only on frames the mask drops
    mask = torch.ones(2, 6)
    mask[1, 4:] = 0
    assert all(float(v) == 0.0 for v in latent_losses(pred, target, mask))
    pos, vel, acc = latent_losses(pred, target)
    assert float(pos) == pytest.approx(5.0 * 2 / 12)
    assert float(vel) > 0 and float(acc) > 0


# --- trainings ----------------------------------------------------------------------------


def basis_poses(frames: int, seed: int) -> np.ndarray:
    """``(T, 24, 3)`` poses (rad) on a 6-d family: fixed random basis poses mixed by smooth
    random weights (the family a 10-d code can hold; each seed gives another motion)."""
    basis = np.random.default_rng(99).normal(scale=0.4, size=(6, 24, 3))
    weights = smooth_poses(frames, seed, amplitude=1.5)[:, :6, 0]  # (T, 6)
    return np.einsum("tk,kjc->tjc", weights, basis)


def test_pose_codec_training_reduces_error(tmp_path: Path) -> None:
    poses = np.concatenate([basis_poses(200, seed) for seed in range(3)])
    config = PoseCodecTrainConfig(hidden=64, epochs=12, batch_size=64, lr=3e-3, seed=1)
    rows: list[dict] = []
    codec, history = train_pose_codec(poses, config, progress=lambda e, n, row: rows.append(row))
    json.dumps(history)
    assert len(rows) == 12 and history["validation_poses"] == 60
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        untrained = PoseCodec(config.hidden, config.code_size)
    held_out = basis_poses(100, 7)  # a motion not seen in training, same family
    before = evaluate_pose_codec(untrained, held_out)
    after = evaluate_pose_codec(codec, held_out)
    assert after["feature_mse"] < 0.2 * before["feature_mse"]
    assert after["angle_deg"] < 0.5 * before["angle_deg"]
    assert history["epochs"][-1]["val_mse"] < 0.3 * history["epochs"][0]["val_mse"]


def test_pose_codec_resume_continues(tmp_path: Path) -> None:
    poses = smooth_poses(120, 3)
    config = PoseCodecTrainConfig(hidden=16, epochs=4, batch_size=32, seed=2)
    straight, h_straight = train_pose_codec(poses, config)
    ckpt = tmp_path / "codec.pt"
    train_pose_codec(
        poses, PoseCodecTrainConfig(**{**asdict(config), "epochs": 2}), checkpoint=ckpt
    )
    resumed, h_resumed = train_pose_codec(poses, config, checkpoint=ckpt, resume=True)
    assert [r["epoch"] for r in h_resumed["epochs"]] == [1, 2, 3, 4]
    for a, b in zip(h_straight["epochs"], h_resumed["epochs"], strict=True):
        assert a["train_mse"] == pytest.approx(b["train_mse"], rel=1e-6)
    for key, value in straight.state_dict().items():
        torch.testing.assert_close(resumed.state_dict()[key], value)


def test_garment_joint_weights_follow_the_kinematic_tree() -> None:
    """A garment skinned half to the left knee and half to the spine: the joints whose rotation
    moves it (knee, hip above it, spine1 above spine2) weigh most, the rest the floor."""
    skinning = torch.zeros(10, 24)
    skinning[:5, 4] = 1.0  # left knee
    skinning[5:, 6] = 1.0  # spine2
    weights = garment_joint_weights(skinning)  # joints 1..23
    assert weights.shape == (23,) and weights.mean() == pytest.approx(1.0)
    # Index j - 1 holds joint j: left hip 0, spine1 2, left knee 3, spine2 5.
    assert weights.max() == pytest.approx(weights[0])
    for index in (2, 3, 5):
        assert weights[index] == pytest.approx(weights[0])
    floor = weights[[1, 4, 6, 15, 19]]  # right hip, right knee, left ankle, shoulder, wrist
    torch.testing.assert_close(floor, torch.full((5,), float(weights.min())))
    assert float(weights.min() / weights.max()) == pytest.approx(0.1)  # the default floor
    # Floor 0 leaves the joints that move none of the garment out of the loss.
    unfloored = garment_joint_weights(skinning, floor=0.0)
    assert unfloored.mean() == pytest.approx(1.0)
    torch.testing.assert_close(unfloored.nonzero().flatten(), torch.tensor([0, 2, 3, 5]))


def test_garment_weighting_spends_the_code_on_the_weighted_joints() -> None:
    """Poses with two factors of motion in the legs and two larger ones elsewhere: a 2-d code
    holds one pair. The uniform loss keeps the larger, weighting the legs keeps the legs' (their
    error falls, the rest's rises); a weighting without weights, or an unknown one, is refused."""
    legs = [1, 2, 4, 5]  # hips and knees

    def poses_of(frames: int, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        t = np.arange(frames)[:, None] / 30.0
        factors = np.sin(2 * np.pi * np.array([0.7, 1.1, 0.5, 1.3]) * t + rng.uniform(0, 6, 4))
        directions = np.random.default_rng(0).normal(size=(4, 24, 3))  # fixed by the joints
        mask = np.zeros((24, 1))
        mask[legs] = 1.0
        leg_part = np.einsum("tk,kjc->tjc", 0.3 * factors[:, :2], directions[:2]) * mask
        rest = np.einsum("tk,kjc->tjc", factors[:, 2:], directions[2:]) * (1 - mask)
        return leg_part + 0.3 * rest

    weights = torch.full((23,), 0.05)
    weights[[j - 1 for j in legs]] = 5.0
    base = dict(hidden=64, code_size=2, epochs=30, batch_size=64, lr=3e-3, seed=3)
    poses = poses_of(600, 5)
    uniform, _ = train_pose_codec(poses, PoseCodecTrainConfig(**base))
    weighted, history = train_pose_codec(
        poses, PoseCodecTrainConfig(**base, joint_weighting="garment"), joint_weights=weights
    )
    assert history["joint_weights"][0] == 5.0
    held_out = torch.as_tensor(poses_of(200, 6), dtype=torch.float32)
    features = pose_to_features(held_out).reshape(-1, 23, 9)

    def errors(codec: PoseCodec) -> tuple[float, float]:
        with torch.no_grad():
            decoded = codec(held_out).reshape(-1, 23, 9)
        per_joint = (decoded - features).square().mean((0, 2))
        chosen = torch.zeros(23, dtype=torch.bool)
        chosen[[j - 1 for j in legs]] = True
        return float(per_joint[chosen].mean()), float(per_joint[~chosen].mean())

    (legs_u, rest_u), (legs_w, rest_w) = errors(uniform), errors(weighted)
    assert legs_w < 0.2 * legs_u and rest_w > 5 * rest_u
    with pytest.raises(ValueError, match="missing"):
        train_pose_codec(poses, PoseCodecTrainConfig(**base, joint_weighting="garment"))
    with pytest.raises(ValueError, match="unknown joint_weighting"):
        PoseCodecTrainConfig(joint_weighting="arms")
    with pytest.raises(ValueError, match="joint_weight_floor"):
        PoseCodecTrainConfig(joint_weighting="garment", joint_weight_floor=-0.1)


N_VERTS = 6
LATENT = 12


def _linear_maps() -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(5)
    to_garment = torch.randn(N_VERTS * 3, 10, generator=g) * 0.05  # pose code → X (m)
    to_latent = torch.randn(LATENT, N_VERTS * 3, generator=g) * 10.0  # X → z
    return to_garment, to_latent


def synthetic_set(lengths=(70, 60, 80, 50, 64), splits=None, fps=None) -> CanonicalSet:
    """Sequences whose canonical garment is a fixed linear map of the pose code (of
    ``_codec()``) plus half the previous frame's, so the target needs memory as well as the
    current pose."""
    splits = splits or ["train", "train", "train", "validation", "train"]
    fps = fps or [30.0] * len(lengths)
    to_garment, _ = _linear_maps()
    codec = _codec()
    poses, trans, canon = [], [], []
    for s, n in enumerate(lengths):
        pose, tr = wandering_motion(n, seed=10 + s)
        with torch.no_grad():
            code = codec.encode(torch.as_tensor(pose, dtype=torch.float32))
        x = (code @ to_garment.T).reshape(n, N_VERTS, 3)
        x[1:] += 0.5 * x[:-1].clone()
        poses.append(pose)
        trans.append(tr)
        canon.append(x.numpy())
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    total = int(offsets[-1])
    return CanonicalSet(
        canonical=np.concatenate(canon).astype(np.float32),
        frame_offsets=offsets,
        betas=np.random.default_rng(0).normal(size=(len(lengths), 10)).astype(np.float32),
        pose=np.concatenate(poses).astype(np.float32),
        trans=np.concatenate(trans).astype(np.float32),
        fps=np.asarray(fps, dtype=np.float32),
        error=np.zeros(total, np.float32),
        max_error=np.zeros(total, np.float32),
        template=np.zeros((N_VERTS, 3), np.float32),
        faces=np.zeros((0, 3), np.int32),
        sources=[f"seq{s}" for s in range(len(lengths))],
        splits=list(splits),
    )


def _encode(x: torch.Tensor) -> torch.Tensor:
    _, to_latent = _linear_maps()
    return x.flatten(1) @ to_latent.T


def _decode(z: torch.Tensor) -> torch.Tensor:
    """The exact inverse of ``_encode`` on the garments of ``synthetic_set`` (the span of the
    code-to-garment map)."""
    to_garment, to_latent = _linear_maps()
    code = z @ torch.linalg.pinv(to_latent @ to_garment).T
    return (code @ to_garment.T).reshape(-1, N_VERTS, 3)


def test_prepare_sequence_resamples_targets() -> None:
    data = synthetic_set(lengths=(61, 30), splits=["train", "validation"], fps=[60.0, 30.0])
    codec = _codec()
    config = RegressorTrainConfig()
    q = prepare_sequence(data, 0, _encode, codec, config, keep_canonical=True)
    assert q.gamma.shape == (31, 42) and q.latent.shape == (31, LATENT)
    torch.testing.assert_close(q.canonical, torch.as_tensor(data.canonical[0:61:2]))
    torch.testing.assert_close(q.latent, _encode(torch.as_tensor(data.canonical[0:61:2])))
    same = prepare_sequence(data, 1, _encode, codec, config)
    assert same.gamma.shape == (30, 42) and same.canonical is None


def _small_config(**changes) -> RegressorTrainConfig:
    base = RegressorTrainConfig(
        hidden=(48, 48), crop_length=30, batch_size=8, crops_per_epoch=32, epochs=25,
        lr=3e-3, seed=3,
    )  # fmt: skip
    return RegressorTrainConfig(**{**asdict(base), **changes})


def test_regressor_training_reduces_loss() -> None:
    data = synthetic_set()
    rows: list[dict] = []
    model, history = train_regressor(
        data, _encode, _codec(), _small_config(), decode=_decode,
        progress=lambda e, n, row: rows.append(row),
    )  # fmt: skip
    json.dumps(history)
    assert len(rows) == 25 and history["train_sequences"] == 4
    assert history["validation_sequences"] == 1
    first, last = history["epochs"][0], history["epochs"][-1]
    assert last["train_pos"] < 0.5 * first["train_pos"]
    assert last["val_pos"] < 0.7 * first["val_pos"]
    assert last["val_vertex_mm"] < first["val_vertex_mm"]
    assert history["decoder_floor_mm"] == pytest.approx(0.0, abs=1e-3)  # the decoder is exact
    # a trained model beats predicting every frame's mean latent on the held-out sequence
    val = prepare_sequence(data, 3, _encode, _codec(), _small_config())
    pred = model.predict(val.gamma, val.betas)
    mean = model.output_mean.expand_as(val.latent)
    assert (
        latent_losses(pred[None], val.latent[None])[0]
        < latent_losses(mean[None], val.latent[None])[0]
    )


def test_regressor_resume_continues(tmp_path: Path) -> None:
    data = synthetic_set(lengths=(40, 35, 30), splits=["train", "train", "validation"])
    config = _small_config(hidden=(16,), epochs=4, crops_per_epoch=8)
    straight, h_straight = train_regressor(data, _encode, _codec(), config)
    ckpt = tmp_path / "regressor.pt"
    _, h_two = train_regressor(data, _encode, _codec(), _small_config(
        hidden=(16,), epochs=2, crops_per_epoch=8), checkpoint=ckpt)  # fmt: skip
    assert ckpt.is_file() and len(h_two["epochs"]) == 2
    resumed, h_resumed = train_regressor(
        data, _encode, _codec(), config, checkpoint=ckpt, resume=True
    )
    assert [r["epoch"] for r in h_resumed["epochs"]] == [1, 2, 3, 4]
    for a, b in zip(h_straight["epochs"], h_resumed["epochs"], strict=True):
        assert a["train_loss"] == pytest.approx(b["train_loss"], rel=1e-6)
        assert a["val_pos"] == pytest.approx(b["val_pos"], rel=1e-6)
    for key, value in straight.state_dict().items():
        torch.testing.assert_close(resumed.state_dict()[key], value)
    with pytest.raises(ValueError):  # another model shape
        train_regressor(
            data, _encode, _codec(), _small_config(hidden=(8,), epochs=5),
            checkpoint=ckpt, resume=True,
        )  # fmt: skip


def test_regressor_needs_train_sequences() -> None:
    data = synthetic_set(lengths=(30, 30), splits=["validation", "test"])
    with pytest.raises(ValueError):
        train_regressor(data, _encode, _codec(), _small_config())


def test_regressor_regularisation_settings() -> None:
    """Weight decay shrinks the weights and input noise changes the fit, both repeatably; at 0
    they leave the training as it was; negative values are refused."""
    data = synthetic_set(lengths=(40, 35, 30), splits=["train", "train", "validation"])
    small = {"hidden": (16,), "epochs": 3, "crops_per_epoch": 8}

    def weights(**changes) -> torch.Tensor:
        model, _ = train_regressor(data, _encode, _codec(), _small_config(**small, **changes))
        return torch.cat([p.detach().flatten() for p in model.parameters()])

    plain = weights()
    torch.testing.assert_close(weights(weight_decay=0.0, input_noise=0.0), plain)
    assert weights(weight_decay=50.0).norm() < 0.9 * plain.norm()  # 0.85 per step
    noisy = weights(input_noise=0.3)
    assert not torch.allclose(noisy, plain)
    torch.testing.assert_close(weights(input_noise=0.3), noisy)
    negative = ({"weight_decay": -1.0}, {"input_noise": -0.1}, {"lambda_posed": -1.0},
                {"lambda_vertex": -1.0})  # fmt: skip
    for bad in negative:
        with pytest.raises(ValueError, match="must not be negative"):
            train_regressor(data, _encode, _codec(), _small_config(**small, **bad))


def test_regressor_posed_term_moves_garments_off_their_planes() -> None:
    """L_posed pushes the decoded garments out of planes that the targets lie behind (vertex 0,
    1 cm behind in every frame); without it the planes are only measured; λ_posed > 0 without
    planes is refused."""
    data = synthetic_set(lengths=(40, 35, 30), splits=["train", "train", "validation"])
    x = torch.as_tensor(data.canonical)
    normal = torch.zeros(x.shape)
    normal[:, 0, 0] = 1.0
    offset = torch.zeros(x.shape[:2])
    offset[:, 0] = -x[:, 0, 0] - 0.01
    valid = torch.zeros(x.shape[:2], dtype=torch.bool)
    valid[:, 0] = True
    planes = PosedPlanes(normal, offset, valid)
    small = {"hidden": (16,), "epochs": 20, "crops_per_epoch": 32}

    def last_row(**changes) -> dict:
        config = _small_config(**small, **changes)
        _, history = train_regressor(data, _encode, _codec(), config, decode=_decode, planes=planes)
        return history["epochs"][-1]

    plain, held = last_row(), last_row(lambda_posed=100.0)
    assert "train_posed" not in plain and held["train_posed"] > 0
    assert plain["val_posed_inside_pct"] > 10.0  # vertex 0 of 6 behind its plane: 16.7 %
    assert held["val_posed_inside_pct"] < 0.6 * plain["val_posed_inside_pct"]
    with pytest.raises(ValueError, match="planes"):
        train_regressor(data, _encode, _codec(), _small_config(**small, lambda_posed=1.0))


def test_regressor_fine_tunes_from_an_initial_one() -> None:
    """``initial`` starts the training from its weights and normalisation (no epochs: the same
    regressor); one of another shape is refused."""
    data = synthetic_set(lengths=(40, 35, 30), splits=["train", "train", "validation"])
    small = {"hidden": (16,), "epochs": 3, "crops_per_epoch": 8}
    first, history = train_regressor(data, _encode, _codec(), _small_config(**small))
    same, _ = train_regressor(
        data, _encode, _codec(), _small_config(**{**small, "epochs": 0}), initial=first
    )
    for key, value in first.state_dict().items():
        torch.testing.assert_close(same.state_dict()[key], value)
    _, tuned_history = train_regressor(
        data, _encode, _codec(), _small_config(**{**small, "epochs": 1, "lr": 1e-5}), initial=first
    )
    # a tiny step from the initial weights, not a fresh start
    assert tuned_history["epochs"][0]["val_pos"] == pytest.approx(
        history["epochs"][-1]["val_pos"], rel=0.05
    )
    with pytest.raises(ValueError, match="initial regressor"):
        train_regressor(
            data, _encode, _codec(), _small_config(hidden=(8,), epochs=1), initial=first
        )


def test_regressor_tunes_the_decoder_end_to_end() -> None:
    """With ``tune_decoder`` the decoder's weights train too (toward the canonical targets, the
    vertex term reported per epoch); without, the decoder given is left as it was. It needs the
    decoder module, and cannot be resumed."""
    data = synthetic_set(lengths=(40, 35, 30), splits=["train", "train", "validation"])
    small = {"hidden": (16,), "epochs": 3, "crops_per_epoch": 8}
    to_garment, to_latent = _linear_maps()

    def decoder_and_decode() -> tuple[torch.nn.Linear, Callable]:
        linear = torch.nn.Linear(LATENT, N_VERTS * 3, bias=False)
        with torch.no_grad():  # _decode's map, as a module
            linear.weight.copy_(to_garment @ torch.linalg.pinv(to_latent @ to_garment))
        return linear, lambda z: linear(z).reshape(-1, N_VERTS, 3)

    fixed, decode = decoder_and_decode()
    before = fixed.weight.detach().clone()
    _, history = train_regressor(
        data, _encode, _codec(), _small_config(**small), decode=decode, decoder=fixed
    )
    torch.testing.assert_close(fixed.weight, before)
    assert "train_vertex_mm" not in history["epochs"][-1]
    tuned, decode = decoder_and_decode()
    _, history = train_regressor(
        data, _encode, _codec(), _small_config(**small, tune_decoder=True), decode=decode,
        decoder=tuned,
    )  # fmt: skip
    assert not torch.allclose(tuned.weight, before)
    assert history["epochs"][-1]["train_vertex_mm"] > 0
    with pytest.raises(ValueError, match="decoder module"):
        train_regressor(data, _encode, _codec(), _small_config(**small, tune_decoder=True))
    with pytest.raises(ValueError, match="cannot be resumed"):
        train_regressor(
            data, _encode, _codec(), _small_config(**small, tune_decoder=True), decode=decode,
            decoder=tuned, resume=True,
        )  # fmt: skip


def test_flagged_frames_are_not_trusted_at_the_model_rate() -> None:
    """A frame the simulation flagged is left out at 30 fps, and so is a frame interpolated
    from it; a set without a record of flagged frames is refused."""
    data = synthetic_set(lengths=(41, 30), splits=["train", "validation"], fps=[50.0, 30.0])
    data.flagged = np.zeros(71, dtype=bool)
    data.flagged[[12, 41 + 3]] = True
    config = _small_config(skip_flagged_frames=True)
    resampled = prepare_sequence(data, 0, _encode, _codec(), config)
    # at 30 fps, frame 7 lies at 50 fps frame 11.67, between frames 11 and 12
    assert resampled.num_frames == 25
    assert resampled.trusted is not None
    assert torch.nonzero(resampled.trusted == 0).flatten().tolist() == [7]
    same = prepare_sequence(data, 1, _encode, _codec(), config)
    assert same.trusted is not None
    assert torch.nonzero(same.trusted == 0).flatten().tolist() == [3]
    assert prepare_sequence(data, 1, _encode, _codec(), _small_config()).trusted is None
    data.flagged = None
    with pytest.raises(ValueError, match="flagged"):
        prepare_sequence(data, 0, _encode, _codec(), config)


def test_decoded_crops_leave_out_untrusted_frames() -> None:
    data = synthetic_set(lengths=(40, 35), splits=["train", "train"])
    data.flagged = np.zeros(75, dtype=bool)
    data.flagged[[2, 50]] = True
    config = _small_config(skip_flagged_frames=True)
    sequences = [prepare_sequence(data, s, _encode, _codec(), config) for s in (0, 1)]
    pred = torch.zeros(2, 6, LATENT)  # crops of 6 frames: set frames 0-5 and 48-53
    out = decoded_crops(pred, sequences, [(0, 0), (1, 8)], _decode)
    assert out is not None
    x, frames = out
    assert frames.tolist() == [0, 1, 3, 4, 5, 48, 49, 51, 52, 53]
    assert x.shape == (10, N_VERTS, 3)
    data.flagged[:] = True
    sequences = [prepare_sequence(data, s, _encode, _codec(), config) for s in (0, 1)]
    assert decoded_crops(pred, sequences, [(0, 0), (1, 8)], _decode) is None


def test_training_skips_what_the_simulation_flagged() -> None:
    """With ``skip_flagged_frames``, the targets of flagged frames (here garbage, with garbage
    posed planes) change nothing of what the regressor and the tuned decoder learn, through
    every loss term; without it they do."""
    data = synthetic_set(lengths=(40, 35, 30), splits=["train", "train", "validation"])
    data.flagged = np.zeros(105, dtype=bool)
    data.flagged[[5, 6, 7, 50]] = True
    x = torch.as_tensor(data.canonical)
    planes = PosedPlanes(
        torch.ones(x.shape), torch.zeros(x.shape[:2]), torch.ones(x.shape[:2], dtype=torch.bool)
    )
    to_garment, to_latent = _linear_maps()
    small = {"hidden": (16,), "epochs": 3, "crops_per_epoch": 8, "lambda_posed": 10.0,
             "tune_decoder": True}  # fmt: skip

    def trained(garbage: bool, skip: bool) -> tuple[list[torch.Tensor], dict]:
        spoilt = CanonicalSet(**{**vars(data), "canonical": data.canonical.copy()})
        bent = PosedPlanes(planes.normal.clone(), planes.offset.clone(), planes.valid)
        if garbage:
            spoilt.canonical[data.flagged] = 0.3
            bent.offset[torch.as_tensor(data.flagged)] = -1.0
        linear = torch.nn.Linear(LATENT, N_VERTS * 3, bias=False)
        with torch.no_grad():
            linear.weight.copy_(to_garment @ torch.linalg.pinv(to_latent @ to_garment))
        model, history = train_regressor(
            spoilt, _encode, _codec(), _small_config(**small, skip_flagged_frames=skip),
            decode=lambda z: linear(z).reshape(-1, N_VERTS, 3), planes=bent, decoder=linear,
        )  # fmt: skip
        return [*model.state_dict().values(), linear.weight.detach()], history

    clean, history = trained(garbage=False, skip=True)
    assert history["flagged_frames_skipped"] == 4
    for a, b in zip(clean, trained(garbage=True, skip=True)[0], strict=True):
        torch.testing.assert_close(a, b)
    unskipped = trained(garbage=True, skip=False)[0]
    assert not all(torch.allclose(a, b) for a, b in zip(clean, unskipped, strict=True))
