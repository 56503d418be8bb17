"""Cloth material for the training-data simulator: SNUG / HOOD's cotton by default, and its
mapping onto the parameters of Newton's Style3D cloth solver.

The physical model is the one SNUG and HOOD use: a StVK membrane with Lamé parameters μ, λ (Pa)
times a thickness h (m), an area density ρ (kg/m²) and a discrete hinge bending energy
``E_b = k_b θ² |e|² / (8 (A0 + A1))`` per interior edge ``e`` with dihedral angle θ and adjacent
rest triangle areas A0, A1. Style3D has a Baraff-Witkin membrane and Bergou's quadratic bending;
``stretch_stiffness``, ``shear_stiffness`` and ``solver_bending_stiffness`` say how we map one
onto the other (see also ``docs/simulation.md``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class ClothMaterial:
    """A woven fabric, isotropic in the plane.

    Attributes:
        area_density: mass per rest area (kg/m²).
        lame_mu: StVK shear modulus μ of the fabric's material (Pa).
        lame_lambda: StVK first Lamé parameter λ (Pa).
        thickness: fabric thickness h (m); membrane stiffnesses are moduli × h (N/m).
        bending: SNUG / HOOD hinge bending coefficient k_b (N·m, i.e. J per rad²).
        friction: Coulomb friction coefficient between fabric and skin (SNUG has none); given
            to both the cloth and the body shape, whose geometric mean the solver uses.
    """

    area_density: float = 0.20022
    lame_mu: float = 2.36e4
    lame_lambda: float = 4.44e4
    thickness: float = 4.7e-4
    bending: float = 3.96e-5
    friction: float = 0.3

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise ValueError(f"material {field.name} must be a number, got {value!r}")
            if not value >= 0.0 or value == float("inf"):
                raise ValueError(f"material {field.name} must be finite and >= 0, got {value}")
        if self.area_density <= 0.0 or self.thickness <= 0.0 or self.lame_mu <= 0.0:
            raise ValueError("material area_density, thickness and lame_mu must be > 0")

    @property
    def stretch_stiffness(self) -> float:
        """Style3D weft and warp stiffness ``k_u = k_v`` (N/m).

        Baraff-Witkin penalises ``k/2 (|F_u| - 1)²`` per rest area, with no coupling between the
        two directions (no Poisson effect), so ``k_u`` acts as a 2D Young's modulus. We take the
        plane-stress Young's modulus of the StVK membrane, ``4 μ (λ + μ) / (λ + 2 μ)`` times h,
        so that pulling a strip (uniaxial stress) stretches it as much as StVK would. Under equal
        biaxial stretch the result is 2 μ / (λ + 2 μ) ≈ 0.52 times as stiff as StVK.
        """
        mu, lam = self.lame_mu, self.lame_lambda
        return self.thickness * 4.0 * mu * (lam + mu) / (lam + 2.0 * mu)

    @property
    def shear_stiffness(self) -> float:
        """Style3D in-plane shear stiffness ``k_s`` (N/m): exactly StVK's μ h.

        StVK's ``μ tr(E²)`` holds ``μ/2 (F_u·F_v)²`` for a pure shear, which is Style3D's shear
        term ``k_s/2 (F_u·F_v)²``.
        """
        return self.thickness * self.lame_mu

    @property
    def solver_bending_stiffness(self) -> float:
        """Style3D (Bergou) edge bending stiffness ``k`` (N·m) for SNUG's ``k_b``.

        Style3D's energy per interior edge is ``k/2 · 3/(A0+A1) · |Σ w_i x_i|²`` with cotangent
        weights ``w`` of the flat rest hinge, which equals ``1.5 k θ² |e|² / (A0 + A1)`` for a
        hinge bent by θ (checked numerically, independent of the triangles' shape). SNUG's is
        ``k_b θ² |e|² / (8 (A0 + A1))``, hence ``k = k_b / 12``. Both take a flat rest angle.
        """
        return self.bending / 12.0

    def to_dict(self) -> dict[str, float]:
        """The material as a JSON-ready dict (keys are the attribute names)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> ClothMaterial:
        """A material from a dict; missing keys keep the cotton defaults.

        Raises:
            ValueError: unknown keys or values that are not finite non-negative numbers.
        """
        if not isinstance(values, dict):
            raise ValueError("a material must be a JSON object of name: number")
        known = {field.name for field in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"unknown material key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}"
            )
        return cls(**values)

    @classmethod
    def load(cls, path: str | Path) -> ClothMaterial:
        """Read a material from a JSON file (an object with any of the attribute names).

        Raises:
            FileNotFoundError: no such file.
            ValueError: not valid JSON, or invalid values (see ``from_dict``).
        """
        path = Path(path)
        try:
            values = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ValueError(
                f"{path}: not a JSON material file ({exc.msg}, line {exc.lineno})"
            ) from exc
        try:
            return cls.from_dict(values)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from exc
