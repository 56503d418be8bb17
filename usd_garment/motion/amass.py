"""AMASS ``.npz`` motions in and out: SMPL-H axis-angle poses (Z-up) to our canonical SMPL motion
(Y-up, root + 21 body joints, hands zero) and back.

Turning the world about the origin turns SMPL's root orientation, but SMPL's root rotation
pivots about the rest pelvis J0, not the origin, so ``trans`` changes as
``trans' = R · (trans + J0) − J0`` with J0 of the body at the motion's betas.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from usd_garment.atomic import atomic_output
from usd_garment.body.betas import as_betas
from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS
from usd_garment.body.model import BodyModel
from usd_garment.motion.resample import resample_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.npz_file import read_npz

#: Column-convention rotation from AMASS's Z-up world to our Y-up canonical frame (−90° about X).
ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

#: Body joints AMASS stores before the hands (root + 21).
AMASS_BODY_JOINTS = 22
AMASS_POSE_SIZE = 156
AMASS_NUM_BETAS = 16


class AmassError(ValueError):
    """An AMASS file that cannot be read."""


def rest_pelvis(body: BodyModel, betas: np.ndarray) -> np.ndarray:
    """``(3,)`` float64 rest pelvis location (m) of ``body`` at ``betas`` ``(10,)``."""
    with torch.no_grad():
        _, joints = body.shaped(torch.as_tensor(betas, dtype=torch.float32)[None])
    return joints[0, 0].double().numpy()


def change_frame(
    pose: np.ndarray, trans: np.ndarray, rotation: np.ndarray, pelvis: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Express an SMPL motion in a frame turned by ``rotation`` about the origin.

    Args:
        pose: ``(T, 24, 3)`` axis-angle (rad); only the root (joint 0) changes.
        trans: ``(T, 3)`` SMPL translation (m).
        rotation: ``(3, 3)`` column-convention rotation from the old frame to the new one.
        pelvis: ``(3,)`` rest pelvis location J0 (m).

    Returns:
        pose and trans in the new frame (float64).
    """
    pose = np.array(pose, dtype=np.float64)
    root = Rotation.from_matrix(rotation) * Rotation.from_rotvec(pose[:, 0])
    pose[:, 0] = root.as_rotvec()
    new_trans = (np.asarray(trans, dtype=np.float64) + pelvis) @ rotation.T - pelvis
    return pose, new_trans


def load_amass(path: str | Path, body: BodyModel, fps: float | None = None) -> SmplMotion:
    """Read an AMASS ``.npz`` as a canonical (Y-up) SMPL motion, optionally resampled to ``fps``.

    Raises:
        AmassError: missing keys, wrong shapes or non-finite values.
    """
    path = Path(path)
    raw = read_npz(path, "not a readable .npz file", AmassError)
    missing = [k for k in ("poses", "trans") if k not in raw]
    if missing:
        raise AmassError(f"{path}: not an AMASS motion (missing {', '.join(missing)})")
    poses = np.asarray(raw["poses"], dtype=np.float64)
    trans = np.asarray(raw["trans"], dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] < 3 * AMASS_BODY_JOINTS or poses.shape[0] == 0:
        raise AmassError(f"{path}: 'poses' must be (T, >=66), got {poses.shape}")
    if trans.shape != (poses.shape[0], 3):
        raise AmassError(f"{path}: 'trans' must be ({poses.shape[0]}, 3), got {trans.shape}")
    if not (np.isfinite(poses).all() and np.isfinite(trans).all()):
        raise AmassError(f"{path}: 'poses' or 'trans' contain NaN or infinite values")
    rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in raw), None)
    if rate_key is None:
        raise AmassError(f"{path}: no 'mocap_framerate' (or 'mocap_frame_rate')")
    src_fps = float(raw[rate_key])
    if not np.isfinite(src_fps) or src_fps <= 0:
        raise AmassError(f"{path}: frame rate must be positive, got {src_fps}")
    try:
        betas = as_betas(raw.get("betas", []))
    except ValueError as exc:
        raise AmassError(f"{path}: {exc}") from None

    t = poses.shape[0]
    pose = np.zeros((t, NUM_JOINTS, 3))
    n = NUM_JOINTS if poses.shape[1] == 3 * NUM_JOINTS else AMASS_BODY_JOINTS  # SMPL keeps hands
    pose[:, :n] = poses[:, : 3 * n].reshape(t, n, 3)
    pose, trans = change_frame(pose, trans, ZUP_TO_YUP, rest_pelvis(body, betas))
    model = "smpl" if n == NUM_JOINTS else "smplh"
    if "surface_model_type" in raw:
        model = str(raw["surface_model_type"])
    motion = SmplMotion(
        betas=betas.astype(np.float32),
        pose=pose.astype(np.float32),
        trans=trans.astype(np.float32),
        fps=src_fps,
        gender=_gender(raw.get("gender")),
        model=model,
    )
    return motion if fps is None else resample_motion(motion, fps)


def save_amass(path: str | Path, motion: SmplMotion, body: BodyModel) -> None:
    """Write ``motion`` (canonical, Y-up) as an AMASS ``.npz`` (Z-up, SMPL-H layout, hands zero).

    Keys: poses ``(T, 156)``, trans ``(T, 3)``, betas ``(16,)``, gender, mocap_framerate.
    """
    pose, trans = change_frame(
        motion.pose, motion.trans, ZUP_TO_YUP.T, rest_pelvis(body, motion.betas)
    )
    poses = np.zeros((motion.num_frames, AMASS_POSE_SIZE))
    poses[:, : 3 * AMASS_BODY_JOINTS] = pose[:, :AMASS_BODY_JOINTS].reshape(motion.num_frames, -1)
    betas = np.zeros(AMASS_NUM_BETAS)
    betas[:NUM_BETAS] = motion.betas
    with atomic_output(path) as tmp, tmp.open("wb") as fh:
        np.savez(
            fh,
            poses=poses,
            trans=trans,
            betas=betas,
            gender=np.array(motion.gender),
            mocap_framerate=np.array(motion.fps),
        )


def _gender(value: object) -> str:
    if value is None:
        return "neutral"
    text = np.asarray(value).reshape(-1)[0]
    text = text.decode() if isinstance(text, bytes) else str(text)
    text = text.strip().lower()
    return text if text in ("male", "female") else "neutral"
