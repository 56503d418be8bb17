"""The generative garment subspace (the paper's Sec. 3.4): a VAE of canonical garments whose
decoder turns a 25-number latent code into a garment, and the loss terms that train it
(reconstruction, Laplacian, the self-supervised collision term, KL)."""

from usd_garment.generative.losses import (
    COLLISION_EPSILON,
    UniformLaplacian,
    collision_loss,
    kl_loss,
    laplacian_loss,
    reconstruction_loss,
)
from usd_garment.generative.vae import (
    LATENT_SIZE,
    OFFICIAL_DECODER,
    DecoderConfig,
    GarmentVAE,
    decoder_bytes,
    load_vae,
    num_parameters,
    save_vae,
)

__all__ = [
    "COLLISION_EPSILON",
    "LATENT_SIZE",
    "OFFICIAL_DECODER",
    "DecoderConfig",
    "GarmentVAE",
    "UniformLaplacian",
    "collision_loss",
    "decoder_bytes",
    "kl_loss",
    "laplacian_loss",
    "load_vae",
    "num_parameters",
    "reconstruction_loss",
    "save_vae",
]
