"""How a model directory stores its learned weights: as float16 (half of float32), or as int8
with one float32 scale per row (about a quarter), so that an ensemble of more members fits the
size a shipped model may take. Loading gives float32 either way.

An int8 weight ``W`` (its first dimension the rows, e.g. a linear layer's outputs) is stored as
``q = round(W / s)`` clamped to ±127 under its own name, and ``s`` (one value a row, the row's
largest magnitude / 127) under the name with :data:`SCALE_SUFFIX`; restored as ``q · s``, each
entry within ``s / 2`` of the trained one. One-dimensional parameters (biases, a layer norm's
gains) stay float16: they are small, and a row of one entry would carry its own scale.
"""

from __future__ import annotations

import torch

#: The storages a model's learned weights may take, the first the default.
STORAGES = ("float16", "int8")
#: Appended to an int8 weight's name to name its row scales.
SCALE_SUFFIX = "#scale"
_INT8_LIMIT = 127


def check_storage(storage: str) -> None:
    """Raise ``ValueError`` unless ``storage`` is one of :data:`STORAGES`."""
    if storage not in STORAGES:
        raise ValueError(f"weights are stored as {' or '.join(STORAGES)}, not '{storage}'")


def stored(name: str, value: torch.Tensor, storage: str) -> dict[str, torch.Tensor]:
    """The tensors that store the learned parameter ``value`` (any shape) named ``name``:
    ``{name: float16}``, or for ``storage`` "int8" and two or more dimensions ``{name: int8,
    name + SCALE_SUFFIX: float32 (rows,)}``.

    Raises:
        ValueError: an unknown ``storage``.
    """
    check_storage(storage)
    if storage == "float16" or value.dim() < 2:
        return {name: value.to(torch.float16)}
    rows = value.detach().float().reshape(value.shape[0], -1)
    scale = rows.abs().amax(dim=1) / _INT8_LIMIT
    scale = torch.where(scale > 0, scale, torch.ones_like(scale))
    q = torch.round(rows / scale[:, None]).clamp(-_INT8_LIMIT, _INT8_LIMIT).to(torch.int8)
    return {name: q.reshape(value.shape), name + SCALE_SUFFIX: scale}


def restored(tensors: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The tensors of a weights file as float32, each int8 weight times its row scales and the
    scales themselves left out (integer tensors without scales are kept as they are).

    Raises:
        KeyError: a scale without its weight.
        RuntimeError: a scale whose length is not its weight's rows.
    """
    out = {}
    for name, value in tensors.items():
        if name.endswith(SCALE_SUFFIX):
            if name.removesuffix(SCALE_SUFFIX) not in tensors:
                raise KeyError(f"{name} scales no weight")
            continue
        scale = tensors.get(name + SCALE_SUFFIX)
        if scale is not None:
            rows = value.float().reshape(value.shape[0], -1)
            if scale.shape != (rows.shape[0],):
                raise RuntimeError(f"{name}: {tuple(scale.shape)} scales for {rows.shape[0]} rows")
            value = (rows * scale.float()[:, None]).reshape(value.shape)
        out[name] = value.float() if value.is_floating_point() else value
    return out
