"""The one exception type for USD input that cannot be read as an animated SMPL body."""

from __future__ import annotations


class UsdInputError(ValueError):
    """A USD file or stage that is missing, unreadable, or not an animated SMPL skeleton."""
