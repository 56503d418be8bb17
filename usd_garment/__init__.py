"""usd-garment: learned, collision-free garments for animated SMPL bodies stored in USD."""

from usd_garment.usd.schema import register_schemas

__version__ = "0.1.0"

register_schemas()
