"""The decoder's best fit of given garments: latent codes found by gradient descent on the
decoding's distance to them. It measures what the subspace can represent at all (a floor under
any regressor's error on those garments), without the encoder, which the shipped models drop."""

from __future__ import annotations

import torch

from usd_garment.generative.vae import GarmentVAE

#: Adam steps and step size of :func:`fit_latents` (the fit of a 25-number code settles well
#: within 300 steps from the regressor's prediction or from zero).
FIT_STEPS = 300
FIT_LR = 0.05


def fit_latents(
    vae: GarmentVAE,
    x: torch.Tensor,
    init: torch.Tensor | None = None,
    steps: int = FIT_STEPS,
    lr: float = FIT_LR,
) -> torch.Tensor:
    """Latent codes ``(T, L)`` whose decodings come closest to the canonical garments ``x``
    ``(T, N, 3)`` (m): Adam on the mean absolute coordinate difference, each frame's code on
    its own (the loss is a sum over frames), from ``init`` ``(T, L)`` (zeros by default). The
    VAE's parameters are left untouched."""
    target = x.detach().float()
    start = torch.zeros(len(target), vae.latent_size) if init is None else init
    z = start.detach().clone().float().requires_grad_(True)
    optimizer = torch.optim.Adam([z], lr=lr)
    was_training = vae.training
    vae.eval()
    try:
        for _ in range(steps):
            optimizer.zero_grad()
            loss = (vae.decode(z) - target).abs().mean(dim=(1, 2)).sum()
            (grad,) = torch.autograd.grad(loss, z)
            z.grad = grad
            optimizer.step()
    finally:
        vae.train(was_training)
    return z.detach()
