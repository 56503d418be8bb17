"""The runtime regressor of the paper's section 4: the motion descriptor γ (a learned pose code
and root motion, heading removed) and the recurrent network R(β, γ) that maps it to the garment's
latent code z."""

from usd_garment.regressor.descriptor import (
    MODEL_FPS,
    describe_motion,
    descriptor_layout,
    descriptor_size,
    motion_descriptor,
)
from usd_garment.regressor.gru import GarmentRegressor
from usd_garment.regressor.pose_code import PoseCodec, features_to_rotations, pose_to_features

__all__ = [
    "MODEL_FPS",
    "GarmentRegressor",
    "PoseCodec",
    "describe_motion",
    "descriptor_layout",
    "descriptor_size",
    "features_to_rotations",
    "motion_descriptor",
    "pose_to_features",
]
