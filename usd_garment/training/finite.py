"""A training setting that is NaN or infinite trains nothing useful (a NaN weight of a loss term
makes every step NaN, and comparisons such as ``value < 0`` let it through), so the training
configs refuse one when they are made."""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any


def require_finite(config: Any) -> None:
    """Raise ``ValueError`` naming the first float field of the dataclass ``config`` whose value
    is NaN or infinite (None and non-float fields are not checked; ``dataclasses.fields``
    raises ``TypeError`` for anything but a dataclass)."""
    for item in fields(config):
        value = getattr(config, item.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{item.name} must be a finite number, got {value}")
