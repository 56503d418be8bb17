"""Green–Lagrange strain of a triangle mesh against its rest triangles: E = ½(FᵀF − I) with F the
deformation gradient of each triangle (3×2, from the rest triangle's own 2D frame)."""

from __future__ import annotations

import torch


class TriangleStrain(torch.nn.Module):
    """Strain of deformed copies of one rest mesh.

    Args:
        rest: ``(N, 3)`` rest vertices (m).
        faces: ``(F, 3)`` triangles.
    """

    faces: torch.Tensor
    rest_inverse: torch.Tensor

    def __init__(self, rest: torch.Tensor, faces: torch.Tensor) -> None:
        super().__init__()
        faces = torch.as_tensor(faces, dtype=torch.int64)
        rest = torch.as_tensor(rest, dtype=torch.float64)
        a, b, c = rest[faces].unbind(-2)
        e1, e2 = b - a, c - a
        u = torch.nn.functional.normalize(e1, dim=-1)
        n = torch.cross(e1, e2, dim=-1)
        v = torch.nn.functional.normalize(torch.cross(n, e1, dim=-1), dim=-1)
        # Rest edges in the triangle's 2D frame (u along the first edge): D_m (F, 2, 2).
        d_m = torch.stack(
            [torch.stack([(e1 * u).sum(-1), (e2 * u).sum(-1)], -1),
             torch.stack([(e1 * v).sum(-1), (e2 * v).sum(-1)], -1)], dim=-2,
        )  # fmt: skip
        self.register_buffer("faces", faces)
        self.register_buffer("rest_inverse", torch.linalg.inv(d_m).float())

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        """Green–Lagrange strain tensors ``(B, F, 2, 2)`` of deformed vertices ``(B, N, 3)``."""
        a, b, c = points[:, self.faces].unbind(-2)  # (B, F, 3) each
        d_s = torch.stack([b - a, c - a], dim=-1)  # (B, F, 3, 2)
        f = d_s @ self.rest_inverse.to(points.dtype)
        eye = torch.eye(2, dtype=points.dtype, device=points.device)
        return 0.5 * (f.transpose(-1, -2) @ f - eye)

    def energy(self, points: torch.Tensor) -> torch.Tensor:
        """E_strain ``(B,)``: Σ over triangles of ‖E‖²_F (Frobenius), per frame."""
        return self.forward(points).square().sum((-1, -2)).sum(-1)
