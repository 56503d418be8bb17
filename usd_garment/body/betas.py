"""Shape coefficients: one way to bring a betas vector of any length to the model's 10."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from usd_garment.body.joints import NUM_BETAS

#: Largest magnitude of a shape coefficient accepted from user input (USD ``smpl:betas``,
#: ``--betas``). Betas are in standard deviations of the body's shape population (procedural
#: shapes use ±2, about 95% of it); past ±5 the linear shape space gives no human body and the
#: value is almost surely wrong units or a corrupt file.
MAX_ABS_BETA = 5.0


def as_betas(values: ArrayLike, max_abs: float | None = None) -> np.ndarray:
    """``(10,)`` float64 betas from ``values``: longer vectors (SMPL-H's 16) are cut, shorter
    ones zero-padded.

    Args:
        values: ``(K,)`` shape coefficients (standard deviations), any K.
        max_abs: when given, the largest accepted ``|β|`` among the 10 kept (e.g.
            :data:`MAX_ABS_BETA`); coefficients past the 10th are ignored by the model and not
            checked.

    Raises:
        ValueError: a NaN or infinite value, or a kept value beyond ``max_abs``.
    """
    flat = np.asarray(values, dtype=np.float64).reshape(-1)[:NUM_BETAS]
    if not np.isfinite(flat).all():
        raise ValueError("betas contain NaN or infinite values")
    if max_abs is not None and flat.size and np.abs(flat).max() > max_abs:
        k = int(np.argmax(np.abs(flat)))
        raise ValueError(
            f"betas[{k}] = {flat[k]:g} is outside the body's shape space (|beta| <= {max_abs:g})"
        )
    out = np.zeros(NUM_BETAS)
    out[: flat.size] = flat
    return out
