"""Garment methods: one interface (:class:`GarmentMethod`), a registry, and the baselines."""

from usd_garment.methods.base import GarmentMethod, available_methods, get_method, register_method
from usd_garment.methods.lbs import LbsMethod, LbsPushOutMethod
from usd_garment.methods.learned import (
    LearnedCanonicalMethod,
    LearnedMethod,
    LearnedPreimageMethod,
    LearnedPushOutMethod,
)
from usd_garment.methods.simulation import SimulationMethod

register_method(LbsMethod.name, LbsMethod)
register_method(LbsPushOutMethod.name, LbsPushOutMethod)
register_method(SimulationMethod.name, SimulationMethod)
register_method(LearnedMethod.name, LearnedMethod)
register_method(LearnedPushOutMethod.name, LearnedPushOutMethod)
register_method(LearnedCanonicalMethod.name, LearnedCanonicalMethod)
register_method(LearnedPreimageMethod.name, LearnedPreimageMethod)

__all__ = ["GarmentMethod", "available_methods", "get_method", "register_method"]
