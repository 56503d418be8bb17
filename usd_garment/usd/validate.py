"""Validate a USD layer with ``pxr.UsdValidation`` (usd-core ships no ``usdchecker``)."""

from __future__ import annotations

from pathlib import Path

from pxr import Usd, UsdValidation


def validate_layer(path: str | Path) -> list[str]:
    """Run every registered validator on the stage of ``path``; return the error messages
    (warnings and infos are left out). An empty list means the layer is valid."""
    stage = Usd.Stage.Open(str(path))
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [
        error.GetErrorAsString()
        for error in context.Validate(stage)
        if error.GetType() == UsdValidation.ValidationErrorType.Error
    ]
