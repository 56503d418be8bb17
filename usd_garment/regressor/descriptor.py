"""The motion descriptor γ of the paper's section 4: per frame, the pose code and the velocities
and accelerations of the pose code, of the root translation and of the root rotation, with the
body's heading (its rotation about the up axis Y) removed so that where the body faces does not
matter.

Layout of γ ``(T, 42)`` for a 10-d pose code (h = 1/fps seconds per frame):

- ``0:10`` code: the pose code θ̄ of joints 1..23 (code units);
- ``10:20`` code_vel: dθ̄/dt (1/s); ``20:30`` code_acc: d²θ̄/dt² (1/s²);
- ``30:33`` trans_vel: root translation velocity dH/dt, heading frame (m/s);
- ``33:36`` trans_acc: root translation acceleration d²H/dt², heading frame (m/s²);
- ``36:39`` rot_vel: root angular velocity ω, heading frame (rad/s);
- ``39:42`` rot_acc: root angular acceleration dω/dt, heading frame (rad/s²).

Derivatives are backward finite differences, as the paper's official code: ``v[t] = (x[t] −
x[t−1]) / h``, ``a[t] = (v[t] − v[t−1]) / h``. Velocities are defined from frame 1 and
accelerations from frame 2; the frames before (padding ``"repeat"``, the default) repeat the
first defined value so a clip that starts in motion does not begin with a spurious jump, or
(``"zeros"``, the official code's choice) are zero. With a single frame every derivative is 0.

The heading frame of frame t is the world frame turned by the root's twist ψ_t about Y (from
the swing-twist split of the root rotation, R_root = R_y(ψ) · R_swing): its axes are the body's
right-ish X, up Y and forward-ish Z, with no tilt. World velocities and accelerations are
computed first and then expressed in the heading frame of their own frame (before the padding
of the first frames), so γ is unchanged by turning the whole motion about Y or shifting it. The
root's angular velocity is the world one, ω = log(R_t R_{t−1}ᵀ) / h, in the heading frame: yaw
rate on Y, tilt rates on X and Z, where the paper uses Euler-angle rates (which wrap and depend
on the heading). The regressor is trained on motions resampled to :data:`MODEL_FPS`;
:func:`describe_motion` does that resampling.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import torch

from usd_garment.motion.cuts import motion_cuts
from usd_garment.motion.resample import resample_motion, resampled_cuts
from usd_garment.motion.sequence import SmplMotion
from usd_garment.regressor.pose_code import PoseCodec

#: Frame rate of the regressor (Hz): its motions are resampled to it, as in the paper's code.
MODEL_FPS: float = 30.0
#: Entries of γ besides the pose code and its derivatives: root translation and rotation
#: velocities and accelerations (3 each).
NUM_ROOT_FEATURES: int = 12
#: Frame paddings of the first velocities and accelerations.
PADDINGS = ("repeat", "zeros")
#: Frames encoded at once by the pose codec.
_CODE_CHUNK = 8192


def descriptor_size(code_size: int = 10) -> int:
    """Entries of γ for a pose code of ``code_size`` (42 for the paper's 10)."""
    return 3 * code_size + NUM_ROOT_FEATURES


def descriptor_layout(code_size: int = 10) -> dict[str, slice]:
    """Named slices of γ (see the module docstring)."""
    c = code_size
    names = ("code", "code_vel", "code_acc")
    layout = {name: slice(i * c, (i + 1) * c) for i, name in enumerate(names)}
    for i, name in enumerate(("trans_vel", "trans_acc", "rot_vel", "rot_acc")):
        layout[name] = slice(3 * c + 3 * i, 3 * c + 3 * (i + 1))
    return layout


def _pad_front(raw: torch.Tensor, frames: int, padding: str) -> torch.Tensor:
    """``(frames, D)`` from the ``(frames − k, D)`` values defined at the last frames."""
    out = raw.new_zeros((frames, raw.shape[-1]))
    k = frames - raw.shape[0]
    if raw.shape[0] == 0:
        return out
    out[k:] = raw
    if padding == "repeat":
        out[:k] = raw[:1]
    return out


def _derivatives(x: torch.Tensor, dt: float, padding: str) -> tuple[torch.Tensor, torch.Tensor]:
    """Backward-difference velocity and acceleration ``(T, D)`` of a signal ``(T, D)``."""
    vel = (x[1:] - x[:-1]) / dt
    acc = (vel[1:] - vel[:-1]) / dt
    t = x.shape[0]
    return _pad_front(vel, t, padding), _pad_front(acc, t, padding)


def _quaternions(rotvec: torch.Tensor) -> torch.Tensor:
    """Unit quaternions ``(..., 4)`` (w, x, y, z) of axis-angle vectors ``(..., 3)`` (rad)."""
    angle = rotvec.norm(dim=-1, keepdim=True)
    half = 0.5 * angle
    # sin(angle/2) / angle = 0.5 · sinc(half / π), finite at 0
    return torch.cat([torch.cos(half), 0.5 * torch.sinc(half / torch.pi) * rotvec], dim=-1)


def _quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a ⊗ b`` of quaternions ``(..., 4)`` (w, x, y, z)."""
    aw, av = a[..., :1], a[..., 1:]
    bw, bv = b[..., :1], b[..., 1:]
    w = aw * bw - (av * bv).sum(-1, keepdim=True)
    v = aw * bv + bw * av + torch.cross(av, bv, dim=-1)
    return torch.cat([w, v], dim=-1)


def _quat_log(q: torch.Tensor) -> torch.Tensor:
    """Axis-angle vectors ``(..., 3)`` (rad, angle in [0, π]) of unit quaternions ``(..., 4)``."""
    q = torch.where(q[..., :1] < 0, -q, q)
    w, v = q[..., :1], q[..., 1:]
    n = v.norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(n, w)
    scale = torch.where(n > 1e-12, angle / n.clamp_min(1e-12), 2.0 / w.clamp_min(1e-12))
    return v * scale


def _to_heading_frame(vectors: torch.Tensor, heading: torch.Tensor) -> torch.Tensor:
    """World vectors ``(T, 3)`` expressed in the heading frames ``(T,)`` (rad about Y): R_y(−ψ)v."""
    c, s = torch.cos(heading), torch.sin(heading)
    x, y, z = vectors.unbind(-1)
    return torch.stack([c * x - s * z, y, s * x + c * z], dim=-1)


def root_features(
    root_rotvec: torch.Tensor, trans: torch.Tensor, fps: float = MODEL_FPS, padding: str = "repeat"
) -> torch.Tensor:
    """Root velocities and accelerations ``(T, 12)`` in each frame's heading frame.

    Args:
        root_rotvec: ``(T, 3)`` root (pelvis) rotation, axis-angle (rad), Y-up world frame.
        trans: ``(T, 3)`` root translation (m).
        fps: frame rate of the samples (Hz).
        padding: ``"repeat"`` or ``"zeros"`` for the first frames (see the module docstring).

    Returns:
        ``[trans_vel (m/s), trans_acc (m/s²), rot_vel (rad/s), rot_acc (rad/s²)]`` per frame.
    """
    dt = 1.0 / float(fps)
    q = _quaternions(root_rotvec.to(torch.float64))  # (T, 4)
    heading = 2.0 * torch.atan2(q[:, 2], q[:, 0])  # twist about Y, rad
    t = q.shape[0]
    trans = trans.to(torch.float64)
    conj = q * q.new_tensor([1.0, -1.0, -1.0, -1.0])
    omega = _quat_log(_quat_mul(q[1:], conj[:-1])) / dt  # (T − 1, 3) world angular velocity
    parts = (trans[1:] - trans[:-1]) / dt, omega  # (T − 1, 3) world velocities
    out = []
    for vel in parts:
        acc = (vel[1:] - vel[:-1]) / dt  # (T − 2, 3)
        vel_h = _to_heading_frame(vel, heading[1:])
        acc_h = _to_heading_frame(acc, heading[2:])
        out += [_pad_front(vel_h, t, padding), _pad_front(acc_h, t, padding)]
    return torch.cat(out, dim=-1)


@torch.no_grad()
def motion_descriptor(
    pose: torch.Tensor | np.ndarray,
    trans: torch.Tensor | np.ndarray,
    codec: PoseCodec,
    fps: float = MODEL_FPS,
    padding: str = "repeat",
    cuts: Sequence[int] = (),
) -> torch.Tensor:
    """The motion descriptor γ ``(T, 3·code_size + 12)`` (42 for a 10-d code) of a motion; with
    ``cuts`` (frames where the motion starts anew, ``motion_cuts``), of each run between them on
    its own, its first derivatives padded as a motion's (a root teleported 0.5 m in a frame
    is 15 m/s to the regressor otherwise, and its GRU took 0.6 s to settle).

    Args:
        pose: ``(T, 24, 3)`` local axis-angle rotations (rad), SMPL order, Y-up world frame.
        trans: ``(T, 3)`` root translation (m).
        codec: the pose codec giving θ̄.
        fps: frame rate of the samples (Hz); the regressor expects :data:`MODEL_FPS`.
        padding: ``"repeat"`` or ``"zeros"`` for the first frames' derivatives.
        cuts: frames (0 < k < T, increasing) where a run starts.

    Returns:
        float32 γ on the codec's device, laid out as :func:`descriptor_layout` (no gradients).

    Raises:
        ValueError: bad shapes, fps or padding.
    """
    if padding not in PADDINGS:
        raise ValueError(f"padding must be one of {PADDINGS}, got {padding!r}")
    if cuts:
        ends = (0, *cuts, len(pose))
        runs = itertools.pairwise(ends)
        return torch.cat(
            [motion_descriptor(pose[a:b], trans[a:b], codec, fps, padding) for a, b in runs]
        )
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    device = next(codec.parameters()).device
    # float64 for the root terms: second differences at 30 fps amplify rounding 900-fold
    pose = torch.as_tensor(pose, device=device).to(torch.float64)
    trans = torch.as_tensor(trans, device=device).to(torch.float64)
    t = pose.shape[0]
    if pose.shape != (t, 24, 3) or trans.shape != (t, 3) or t == 0:
        raise ValueError(
            f"pose must be (T, 24, 3) and trans (T, 3) with T > 0, got "
            f"{tuple(pose.shape)} and {tuple(trans.shape)}"
        )
    code = torch.cat([codec.encode(chunk.float()) for chunk in pose.split(_CODE_CHUNK)])
    code_vel, code_acc = _derivatives(code.to(torch.float64), 1.0 / float(fps), padding)
    root = root_features(pose[:, 0], trans, fps, padding)
    return torch.cat([code.to(torch.float64), code_vel, code_acc, root], dim=-1).float()


def at_model_rate(motion: SmplMotion, cuts: Sequence[int]) -> tuple[SmplMotion, tuple[int, ...]]:
    """``motion`` resampled to :data:`MODEL_FPS` (``motion`` itself when it already runs at that
    rate), and its ``cuts`` (its frames where it starts anew, ``motion_cuts``) at that rate."""
    resampled = resample_motion(motion, MODEL_FPS, cuts)
    return resampled, resampled_cuts(cuts, motion.fps, MODEL_FPS, resampled.num_frames)


def describe_motion(
    motion: SmplMotion, codec: PoseCodec, padding: str = "repeat"
) -> tuple[torch.Tensor, SmplMotion]:
    """γ ``(T', 42)`` of ``motion`` resampled to :data:`MODEL_FPS`, and that resampled motion
    (:func:`at_model_rate`); the runs between its cuts each on their own."""
    resampled, cuts = at_model_rate(motion, motion_cuts(motion))
    gamma = motion_descriptor(resampled.pose, resampled.trans, codec, MODEL_FPS, padding, cuts)
    return gamma, resampled
