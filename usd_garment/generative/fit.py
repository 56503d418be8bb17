"""The decoder's best fit of given garments: latent codes found by gradient descent on the
decoding's distance to them. It measures what the subspace can represent at all (a floor under
any regressor's error on those garments), without the encoder, which the shipped models drop."""

from __future__ import annotations

from collections.abc import Callable

import torch

#: Adam steps and step size of :func:`fit_latents` (the fit of a 25-number code settles well
#: within 300 steps from the regressor's prediction or from zero).
FIT_STEPS = 300
FIT_LR = 0.05


def fit_latents(
    decode: Callable[[torch.Tensor], torch.Tensor],
    x: torch.Tensor,
    init: torch.Tensor,
    steps: int = FIT_STEPS,
    lr: float = FIT_LR,
) -> torch.Tensor:
    """Latent codes ``(T, L)`` whose decodings come closest to the canonical garments ``x``
    ``(T, N, 3)`` (m): Adam on the mean absolute coordinate difference, each frame's code on
    its own (the loss is a sum over frames), from ``init`` ``(T, L)``.

    Args:
        decode: codes ``(T, L)`` → garments ``(T, N, 3)`` of networks in evaluation mode (a
            model's :meth:`~usd_garment.methods.learned_model.LearnedModel.decode`); their
            parameters are left untouched."""
    target = x.detach().float()
    z = init.detach().clone().float().requires_grad_(True)
    optimizer = torch.optim.Adam([z], lr=lr)
    for _ in range(steps):
        optimizer.zero_grad()
        loss = (decode(z) - target).abs().mean(dim=(1, 2)).sum()
        (grad,) = torch.autograd.grad(loss, z)
        z.grad = grad
        optimizer.step()
    return z.detach()
