"""The learned 10-d pose code θ̄ of the paper's motion descriptor: an autoencoder of the body
pose (joints 1..23, the root left out) whose encoder maps SMPL's pose-blendshape features
(R − I of each joint, 207 values) through one hidden layer to the code, as the paper's official
pose encoder does (207 → 500 → 10)."""

from __future__ import annotations

from typing import Any

import torch

from usd_garment.body.joints import NUM_JOINTS
from usd_garment.body.lbs import batch_rodrigues, pose_features

#: Pose features per frame: 9 entries of (R − I) for each of the 23 non-root joints.
NUM_POSE_FEATURES: int = 9 * (NUM_JOINTS - 1)


def pose_to_features(pose: torch.Tensor) -> torch.Tensor:
    """SMPL pose-blendshape features ``(B, 207)``: (R − I) of joints 1..23, flattened.

    Args:
        pose: ``(B, 24, 3)`` local axis-angle rotations (rad), SMPL joint order. The root
            (joint 0) is ignored.
    """
    return pose_features(batch_rodrigues(pose))


def features_to_rotations(features: torch.Tensor) -> torch.Tensor:
    """The rotations nearest to decoded features: ``(B, 207)`` → ``(B, 23, 3, 3)``.

    ``features + I`` is projected onto SO(3) by SVD (the closest rotation in Frobenius norm).
    """
    eye = torch.eye(3, dtype=features.dtype, device=features.device)
    mats = features.reshape(*features.shape[:-1], NUM_JOINTS - 1, 3, 3) + eye
    u, _, vh = torch.linalg.svd(mats)
    det = torch.det(u @ vh)
    fix = torch.ones_like(mats[..., 0, :])  # (..., 3): flip the last axis where det < 0
    fix[..., 2] = torch.sign(det)
    return (u * fix[..., None, :]) @ vh


class PoseCodec(torch.nn.Module):
    """Autoencoder of the body pose: ``encode`` gives the pose code θ̄, ``decode`` the features.

    The encoder is ``Linear(207, hidden) → ReLU → Linear(hidden, code_size)``; the decoder mirrors
    it back to the 207 pose features (R − I of joints 1..23), from which
    :func:`features_to_rotations` recovers rotation matrices.
    """

    def __init__(self, hidden: int = 500, code_size: int = 10) -> None:
        super().__init__()
        self.hidden = int(hidden)
        self.code_size = int(code_size)
        self.encoder = torch.nn.Sequential(
            torch.nn.Linear(NUM_POSE_FEATURES, self.hidden),
            torch.nn.ReLU(),
            torch.nn.Linear(self.hidden, self.code_size),
        )
        self.decoder = torch.nn.Sequential(
            torch.nn.Linear(self.code_size, self.hidden),
            torch.nn.ReLU(),
            torch.nn.Linear(self.hidden, NUM_POSE_FEATURES),
        )

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        """Pose code ``(B, code_size)`` of poses ``(B, 24, 3)`` (axis-angle, rad; root ignored)."""
        return self.encode_features(pose_to_features(pose))

    def encode_features(self, features: torch.Tensor) -> torch.Tensor:
        """Pose code ``(B, code_size)`` of pose features ``(B, 207)``."""
        return self.encoder(features)

    def decode(self, code: torch.Tensor) -> torch.Tensor:
        """Pose features ``(B, 207)`` (R − I of joints 1..23) of codes ``(B, code_size)``."""
        return self.decoder(code)

    def forward(self, pose: torch.Tensor) -> torch.Tensor:
        """Reconstructed pose features ``(B, 207)`` of poses ``(B, 24, 3)``."""
        return self.decode(self.encode(pose))

    def config(self) -> dict[str, Any]:
        """The constructor's arguments (JSON-able): ``PoseCodec.from_config(c)`` rebuilds it."""
        return {"hidden": self.hidden, "code_size": self.code_size}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> PoseCodec:
        """An untrained codec of the shape ``config`` describes (load a state dict into it)."""
        return cls(hidden=int(config["hidden"]), code_size=int(config["code_size"]))
