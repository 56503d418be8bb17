"""Shape coefficients: one way to bring a betas vector of any length to the model's 10."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from usd_garment.body.joints import NUM_BETAS


def as_betas(values: ArrayLike) -> np.ndarray:
    """``(10,)`` float64 betas from ``values``: longer vectors (SMPL-H's 16) are cut, shorter
    ones zero-padded.

    Raises:
        ValueError: a NaN or infinite value.
    """
    flat = np.asarray(values, dtype=np.float64).reshape(-1)[:NUM_BETAS]
    if not np.isfinite(flat).all():
        raise ValueError("betas contain NaN or infinite values")
    out = np.zeros(NUM_BETAS)
    out[: flat.size] = flat
    return out
