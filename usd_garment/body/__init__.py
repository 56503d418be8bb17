"""SMPL-layout body model: joints, LBS, loading, and the embedded default body."""

from usd_garment.body.io import BodyModelError, default_body_path, load_body_model
from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS, SMPL_JOINT_NAMES, SMPL_PARENTS
from usd_garment.body.model import BodyModel, BodyOutput

__all__ = [
    "NUM_BETAS",
    "NUM_JOINTS",
    "SMPL_JOINT_NAMES",
    "SMPL_PARENTS",
    "BodyModel",
    "BodyModelError",
    "BodyOutput",
    "default_body_path",
    "load_body_model",
]
