"""usd-garment: learned, collision-free garments for animated SMPL bodies stored in USD."""

__version__ = "0.1.0"
