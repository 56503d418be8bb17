"""Per-epoch checkpoints of a training run (the pose codec's and the regressor's): the network,
its optimizer and random generator, the epoch and the history, written atomically after every
epoch and read back to resume exactly where the run stopped."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from usd_garment.atomic import atomic_output


def save_checkpoint(
    path: Path,
    kind: str,
    model: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    generator: torch.Generator,
    epoch: int,
    history: dict[str, Any],
    config: dict[str, Any],
) -> None:
    """Write the state after ``epoch`` epochs to ``path`` (``model`` needs a ``config()``)."""
    state = {
        "format": kind,
        "model_config": model.config(),
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "epoch": epoch,
        "history": history,
        "config": config,
        "generator": generator.get_state(),
    }
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def resume_checkpoint(
    path: Path,
    kind: str,
    model: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    generator: torch.Generator,
    device: torch.device | str,
) -> dict[str, Any]:
    """Load the checkpoint ``path`` into ``model``, ``optimizer`` and ``generator``.

    Returns:
        The checkpoint's ``epoch`` (epochs done) and ``history``.

    Raises:
        ValueError: not a checkpoint of ``kind``, or of a network of another architecture.
    """
    state = torch.load(path, map_location=device, weights_only=True)
    if state.get("format") != kind:
        raise ValueError(f"{path}: not a {kind} checkpoint")
    if state["model_config"] != model.config():
        raise ValueError(
            f"{path}: checkpoint model {state['model_config']} differs from {model.config()}"
        )
    model.load_state_dict(state["model"])
    optimizer.load_state_dict(state["optimizer"])
    generator.set_state(state["generator"])
    return {"epoch": int(state["epoch"]), "history": state["history"]}
