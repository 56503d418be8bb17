"""Making and consuming training data: simulated datasets (``dataset``), and the training of the
learned networks from the canonical training set: the generative garment subspace (``vae``),
the pose codec (``pose``), the garment regressor (``regressor``), all stages into one model
directory (``pipeline``) and their pictures (``plots``). Library calls only; the command line
lives in ``cli/``."""

from usd_garment.training.vae import VaeTrainConfig, evaluate_vae, train_vae

__all__ = ["VaeTrainConfig", "evaluate_vae", "train_vae"]
