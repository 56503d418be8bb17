"""The interface every garment method implements, and the registry the CLI picks methods from."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from usd_garment.body.model import BodyModel
from usd_garment.garment.template import GarmentTemplate
from usd_garment.motion.sequence import SmplMotion

#: Called with the number of frames finished so far.
Progress = Callable[[int], None]


class GarmentMethod(Protocol):
    """Poses a garment template on an animated body.

    Attributes:
        name: the registry name, written to the layer as ``garment:method``.
        version: version of the method or of its trained weights (``garment:modelVersion``).
        settings: the method's parameters, recorded as ``garment:solverSettings`` (JSON).
    """

    name: str
    version: str
    settings: dict[str, float | int | str]

    def predict(
        self,
        motion: SmplMotion,
        body: BodyModel,
        template: GarmentTemplate,
        progress: Progress | None = None,
    ) -> np.ndarray:
        """Posed garment points ``(T, N, 3)`` float32, canonical frame (Y-up, metres)."""
        ...


_REGISTRY: dict[str, Callable[[], GarmentMethod]] = {}


def register_method(name: str, factory: Callable[[], GarmentMethod]) -> None:
    """Make ``factory`` available as ``get_method(name)``."""
    _REGISTRY[name] = factory


def available_methods() -> tuple[str, ...]:
    """Names of the registered methods, sorted."""
    return tuple(sorted(_REGISTRY))


def get_method(name: str) -> GarmentMethod:
    """A new instance of the method called ``name``.

    Raises:
        ValueError: no method has that name.
    """
    if name not in _REGISTRY:
        raise ValueError(f"unknown method '{name}' (available: {', '.join(available_methods())})")
    return _REGISTRY[name]()
