"""Training of the learned networks from the canonical training set: the generative garment
subspace (``vae``), the pose codec (``pose``) and the garment regressor (``regressor``).
Library calls only; the command line lives in ``cli/``."""

from usd_garment.training.vae import VaeTrainConfig, evaluate_vae, train_vae

__all__ = ["VaeTrainConfig", "evaluate_vae", "train_vae"]
