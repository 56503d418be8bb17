"""The SMPL-layout body model M_B(β, θ): shape and pose blendshapes, joint regression and LBS.

One class serves SMPL, SMPL-H (reduced to 24 joints on load) and our embedded default body.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS, SMPL_PARENTS
from usd_garment.body.lbs import (
    batch_rigid_transform,
    batch_rodrigues,
    blend_shapes,
    pose_features,
    skin,
    vertices2joints,
)


@dataclass
class BodyOutput:
    """Result of a body forward pass; B frames, V vertices, J = 24 joints, metres.

    Attributes:
        vertices: ``(B, V, 3)`` posed vertices, root translation included.
        joints: ``(B, J, 3)`` posed joint locations, root translation included.
        transforms: ``(B, J, 4, 4)`` skinning transforms, root translation included, so that
            ``skin(rest_points, weights, transforms)`` poses any rest-space point.
        rest_vertices: ``(B, V, 3)`` shaped and pose-corrected vertices before skinning.
        rest_joints: ``(B, J, 3)`` joints of the shaped body in rest pose.
    """

    vertices: torch.Tensor
    joints: torch.Tensor
    transforms: torch.Tensor
    rest_vertices: torch.Tensor
    rest_joints: torch.Tensor


class BodyModel(torch.nn.Module):
    """A differentiable SMPL-layout body.

    Buffers (float32 unless noted):
        v_template ``(V, 3)``, shapedirs ``(V, 3, 10)``, posedirs ``(V, 3, P)`` with P = 207
        or 0 (no pose blendshapes), J_regressor ``(24, V)``, weights ``(V, 24)``,
        faces ``(F, 3)`` int64.
    """

    v_template: torch.Tensor
    shapedirs: torch.Tensor
    posedirs: torch.Tensor
    J_regressor: torch.Tensor
    weights: torch.Tensor
    faces: torch.Tensor

    def __init__(
        self,
        v_template: np.ndarray,
        shapedirs: np.ndarray,
        posedirs: np.ndarray,
        J_regressor: np.ndarray,
        weights: np.ndarray,
        faces: np.ndarray,
        name: str = "body",
    ) -> None:
        super().__init__()
        v = v_template.shape[0]
        if v_template.shape != (v, 3):
            raise ValueError(f"v_template must be (V, 3), got {v_template.shape}")
        if shapedirs.shape[:2] != (v, 3) or shapedirs.shape[2] < NUM_BETAS:
            raise ValueError(f"shapedirs must be (V, 3, >=10), got {shapedirs.shape}")
        if posedirs.shape[:2] != (v, 3) or posedirs.shape[2] not in (0, 9 * (NUM_JOINTS - 1)):
            raise ValueError(f"posedirs must be (V, 3, 207) or (V, 3, 0), got {posedirs.shape}")
        if J_regressor.shape != (NUM_JOINTS, v):
            raise ValueError(f"J_regressor must be (24, V), got {J_regressor.shape}")
        if weights.shape != (v, NUM_JOINTS):
            raise ValueError(f"weights must be (V, 24), got {weights.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= v:
            raise ValueError("faces must be (F, 3) indices into the vertices")
        f32 = torch.float32
        self.register_buffer("v_template", torch.as_tensor(v_template, dtype=f32))
        self.register_buffer("shapedirs", torch.as_tensor(shapedirs[..., :NUM_BETAS], dtype=f32))
        self.register_buffer("posedirs", torch.as_tensor(posedirs, dtype=f32))
        self.register_buffer("J_regressor", torch.as_tensor(J_regressor, dtype=f32))
        self.register_buffer("weights", torch.as_tensor(weights, dtype=f32))
        self.register_buffer("faces", torch.as_tensor(faces, dtype=torch.int64))
        self.name = name
        self.parents: tuple[int, ...] = SMPL_PARENTS

    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    @property
    def has_pose_blendshapes(self) -> bool:
        return int(self.posedirs.shape[2]) > 0

    def shaped(self, betas: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Rest-pose vertices ``(B, V, 3)`` and joints ``(B, J, 3)`` for betas ``(B, 10)``."""
        v_shaped = self.v_template + blend_shapes(betas, self.shapedirs)
        return v_shaped, vertices2joints(self.J_regressor, v_shaped)

    def forward(
        self,
        betas: torch.Tensor,
        pose: torch.Tensor,
        trans: torch.Tensor | None = None,
    ) -> BodyOutput:
        """Pose the body.

        Args:
            betas: ``(B, 10)`` or ``(10,)`` shape coefficients (broadcast over frames).
            pose: ``(B, 24, 3)`` local axis-angle rotations (rad), SMPL joint order.
            trans: ``(B, 3)`` root translation (m), or None for zero.
        """
        b = pose.shape[0]
        if betas.dim() == 1:  # shaped per frame: the simulations' bodies stay bit for bit
            betas = betas.expand(b, -1)
        v_shaped, rest_joints = self.shaped(betas)
        rot_mats = batch_rodrigues(pose.reshape(b, NUM_JOINTS, 3))
        rest_vertices = v_shaped
        if self.has_pose_blendshapes:
            rest_vertices = v_shaped + blend_shapes(pose_features(rot_mats), self.posedirs)
        joints, transforms = batch_rigid_transform(rot_mats, rest_joints, self.parents)
        if trans is not None:
            joints = joints + trans[:, None]
            transforms = transforms.clone()
            transforms[..., :3, 3] += trans[:, None]
        vertices = skin(rest_vertices, self.weights, transforms)
        return BodyOutput(vertices, joints, transforms, rest_vertices, rest_joints)
