"""Garment methods: one interface (:class:`GarmentMethod`), a registry, and the baselines."""

from usd_garment.methods.base import GarmentMethod, available_methods, get_method, register_method
from usd_garment.methods.lbs import LbsMethod, LbsPushOutMethod
from usd_garment.methods.learned import LEARNED_CLASSES
from usd_garment.methods.simulation import SimulationMethod

register_method(LbsMethod.name, LbsMethod)
register_method(LbsPushOutMethod.name, LbsPushOutMethod)
register_method(SimulationMethod.name, SimulationMethod)
for _learned in LEARNED_CLASSES:
    register_method(_learned.name, _learned)

__all__ = ["GarmentMethod", "available_methods", "get_method", "register_method"]
