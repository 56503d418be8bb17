"""A model's weights stored as int8 with a scale per row: each entry within half a step of the
trained one, loaded back as float32; a file whose scales do not fit its weights is refused."""

from __future__ import annotations

import pytest
import torch

from usd_garment.methods.weight_storage import SCALE_SUFFIX, restored, stored


def test_int8_rows_are_within_half_a_step():
    weight = torch.randn(40, 3, 7, generator=torch.Generator().manual_seed(0))
    weight[5] = 0.0  # a row of zeros keeps a usable scale
    weight[6] *= 1e3  # a large row does not coarsen the others
    tensors = stored("w", weight, "int8")
    assert tensors["w"].dtype == torch.int8 and tensors["w"].shape == weight.shape
    scale = tensors["w" + SCALE_SUFFIX]
    assert scale.dtype == torch.float32 and scale.shape == (40,)
    back = restored(tensors)
    assert list(back) == ["w"] and back["w"].dtype == torch.float32
    error = (back["w"] - weight).abs().reshape(40, -1).amax(dim=1)
    assert torch.all(error <= scale / 2 * (1 + 1e-6))
    assert torch.equal(back["w"][5], weight[5])
    assert error[0] < 0.02 and error[6] > 1.0  # each row's step is its own


def test_vectors_and_float16_storage_are_half_precision():
    bias = torch.linspace(-1.0, 1.0, 9)
    for storage in ("float16", "int8"):
        (name, value), *more = stored("b", bias, storage).items()
        assert name == "b" and not more and torch.equal(value, bias.half())
    assert set(stored("w", torch.ones(3, 4), "float16")) == {"w"}
    with pytest.raises(ValueError, match="float16 or int8"):
        stored("w", torch.ones(3, 4), "int4")


def test_scales_that_do_not_fit_their_weights_are_refused():
    tensors = stored("w", torch.ones(3, 4), "int8")
    with pytest.raises(RuntimeError, match="3 rows"):
        restored({"w": tensors["w"], "w" + SCALE_SUFFIX: torch.ones(2)})
    with pytest.raises(KeyError, match="scales no weight"):
        restored({"v" + SCALE_SUFFIX: torch.ones(3)})
    steps = torch.arange(3, dtype=torch.int64)  # an integer buffer without scales is kept
    assert restored({"n": steps})["n"] is steps
