"""The SMPL motion of a motion file of any kind the project reads: a BVH or AMC capture, an AMASS
``.npz`` or a USD body layer (what ``dataset make --capture`` and ``motion poses`` take)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from usd_garment.body.model import BodyModel
from usd_garment.motion.amass import load_amass
from usd_garment.motion.bvh import (
    ARM_CONTACT_CLEARANCE,
    DEFAULT_COLLARS,
    is_capture_path,
    load_bvh,
)
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.read import read_smpl_motion


def read_motion_file(
    path: str | Path,
    body: BodyModel,
    betas: np.ndarray | None = None,
    arm_clearance: float | None = ARM_CONTACT_CLEARANCE,
    collars: str = DEFAULT_COLLARS,
) -> SmplMotion:
    """The SMPL motion of a BVH capture (``.bvh``, ``.bvh.xz``, ``.bvh.gz``) or an AMC one (its
    ASF beside it), imported as ``import-bvh`` does (``arm_clearance`` and ``collars`` as
    there), an AMASS ``.npz`` or a USD body layer, at its own frame rate; ``betas`` ``(10,)``
    replaces the file's body shape when given.

    Raises:
        BvhError, AmassError, UsdInputError: a file of that kind that cannot be read.
    """
    path = Path(path)
    if is_capture_path(path):
        motion, _ = load_bvh(path, body, betas=betas, arm_clearance=arm_clearance, collars=collars)
        return motion
    motion = load_amass(path, body) if path.suffix == ".npz" else read_smpl_motion(path, body)[0]
    if betas is not None:
        motion.betas = np.asarray(betas, dtype=np.float32)
    return motion
