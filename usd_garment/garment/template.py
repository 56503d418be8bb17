"""A garment template: the rest mesh a garment method deforms, with UVs and its provenance."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Garment names and levels of detail (target vertex counts) the package knows.
GARMENT_NAMES: tuple[str, ...] = ("tshirt", "dress")
LODS: dict[str, int] = {"high": 4400, "medium": 2000, "low": 1000}
#: Version of the recipe that builds templates (``garment.templates``), bumped whenever it
#: changes the output; stored in template files and cache keys.
RECIPE_VERSION = 1


@dataclass
class GarmentTemplate:
    """A garment mesh in the body's rest space (Y-up, metres, β = 0, T-pose).

    Attributes:
        name: garment name, one of ``GARMENT_NAMES``.
        lod: level of detail, a key of ``LODS``.
        vertices: ``(N, 3)`` float32 rest positions (m).
        faces: ``(F, 3)`` int32 triangles, counter-clockwise seen from outside.
        uvs: ``(N, 2)`` float32 texture coordinates in [0, 1].
        body: name of the body model the template was fitted to.
    """

    name: str
    lod: str
    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray
    body: str
