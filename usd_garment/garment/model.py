"""The garment model M_G(X, β, θ) of the paper (Sec. 3.2, Eqs. 8–9): canonical garment points X,
deformed by the diffused shape (and pose) blendshapes, then skinned with the diffused weights
W̃(X) and the body's joints J(β).

Reuses the body's own pieces: joints from ``BodyModel.shaped``, forward kinematics from
``batch_rigid_transform``, skinning from ``blend_transforms`` and ``skin_blended``. Shapes: B
frames, N garment points, J = 24 joints, K = 10 betas. Units: metres and radians.
Differentiable in X, β and θ; runs on any device the body and the fields live on.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from usd_garment.body.joints import NUM_JOINTS
from usd_garment.body.lbs import (
    batch_rigid_transform,
    batch_rodrigues,
    blend_transforms,
    pose_features,
    skin_blended,
)
from usd_garment.body.model import BodyModel
from usd_garment.fields.body_fields import BodyFields, FieldTangent


@dataclass
class Articulation:
    """The pose-dependent part of M_G, independent of X (compute once per frame, reuse).

    Attributes:
        betas: ``(B, K)`` shape coefficients.
        pose_features: ``(B, 9·(J−1))`` (R − I) of every joint but the root (drives B̃p).
        transforms: ``(B, J, 4, 4)`` skinning transforms of J(β) posed by θ, root translation
            included.
    """

    betas: torch.Tensor
    pose_features: torch.Tensor
    transforms: torch.Tensor

    def __getitem__(self, frames: slice) -> Articulation:
        """The articulation of a range of frames."""
        return Articulation(self.betas[frames], self.pose_features[frames], self.transforms[frames])


@dataclass
class GarmentOutput:
    """Result of :meth:`GarmentModel.forward`.

    Attributes:
        vertices: ``(B, N, 3)`` posed garment M_G(X, β, θ) (m).
        unposed: ``(B, N, 3)`` T_G(X, β, θ) = X + B̃s(X, β) + B̃p(X, θ), before skinning (m).
        weights: ``(B, N, J)`` diffused skinning weights W̃(X).
        blended: ``(B, N, 3, 4)`` each point's blended skinning transform, which maps
            ``unposed`` to ``vertices`` (``lbs.blend_transforms``).
    """

    vertices: torch.Tensor
    unposed: torch.Tensor
    weights: torch.Tensor
    blended: torch.Tensor


class GarmentModel(torch.nn.Module):
    """M_G for any garment topology: the diffused fields make it defined for every point X.

    Args:
        body: the body model (joint regressor, kinematic tree).
        fields: the body's diffused fields W̃, B̃s, B̃p (and the canonical SDF).
    """

    def __init__(self, body: BodyModel, fields: BodyFields) -> None:
        super().__init__()
        self.body = body
        self.fields = fields

    def articulation(
        self, betas: torch.Tensor, pose: torch.Tensor, trans: torch.Tensor | None = None
    ) -> Articulation:
        """J(β) posed by θ: the transforms W(·, J(β), θ, ·) applies.

        Args:
            betas: ``(B, K)`` or ``(K,)`` (broadcast over frames).
            pose: ``(B, J, 3)`` local axis-angle rotations (rad).
            trans: ``(B, 3)`` root translation (m), or None for zero.
        """
        b = pose.shape[0]
        if betas.dim() == 1:  # one shape: its joints once, not once per frame
            _, joints = self.body.shaped(betas[None])
            betas, rest_joints = betas.expand(b, -1), joints.expand(b, -1, -1)
        else:
            _, rest_joints = self.body.shaped(betas)
        rot_mats = batch_rodrigues(pose.reshape(b, NUM_JOINTS, 3))
        _, transforms = batch_rigid_transform(rot_mats, rest_joints, self.body.parents)
        if trans is not None:
            transforms = transforms.clone()
            transforms[..., :3, 3] += trans[:, None]
        return Articulation(betas, pose_features(rot_mats), transforms)

    def pose(
        self, x: torch.Tensor, art: Articulation, tangent: FieldTangent | None = None
    ) -> GarmentOutput:
        """Eqs. 9 then 8 for canonical points ``x`` ``(B, N, 3)`` and a precomputed articulation.

        The pose blendshape term is present only when the fields have pose blendshapes.
        ``tangent``: the fields to first order about points near ``x`` (inference: one set of
        lookups per chunk of frames instead of one per frame); None: looked up at ``x``.
        """
        source = tangent if tangent is not None else self.fields
        if (
            (tangent is not None or not torch.is_grad_enabled())  # inference
            and not self.fields.has_pose_dirs
            and bool((art.betas == art.betas[:1]).all())  # one shape (a sync)
        ):
            weights, offsets = source.shaped(x, art.betas[0])  # W̃(X), B̃s(X)·β
            return _skinned(x + offsets, weights, art)
        weights, shape_dirs, pose_dirs = source.all_fields(x)  # W̃(X), B̃s(X), B̃p(X)
        t_g = x + torch.einsum("bk,bnck->bnc", art.betas, shape_dirs)  # Eq. 9
        if pose_dirs is not None:
            t_g = t_g + torch.einsum("bp,bncp->bnc", art.pose_features, pose_dirs)
        return _skinned(t_g, weights, art)  # Eq. 8

    def forward(
        self,
        x: torch.Tensor,
        betas: torch.Tensor,
        pose: torch.Tensor,
        trans: torch.Tensor | None = None,
    ) -> GarmentOutput:
        """M_G(X, β, θ) (+ root translation).

        Args:
            x: ``(B, N, 3)`` canonical garment points (m).
            betas: ``(B, K)`` or ``(K,)`` shape coefficients.
            pose: ``(B, J, 3)`` local axis-angle rotations (rad).
            trans: ``(B, 3)`` root translation (m), or None for zero.
        """
        return self.pose(x, self.articulation(betas, pose, trans))


def _skinned(t_g: torch.Tensor, weights: torch.Tensor, art: Articulation) -> GarmentOutput:
    """Points before skinning ``t_g`` ``(B, N, 3)`` (m) skinned with ``weights`` ``(B, N, J)``
    (Eq. 8)."""
    blended = blend_transforms(weights, art.transforms)
    return GarmentOutput(skin_blended(t_g, blended), t_g, weights, blended)
