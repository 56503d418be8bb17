"""Shared fixtures: a tiny synthetic SMPL-layout body, and the body tests should use."""

from __future__ import annotations

import numpy as np
import pytest

from tests.synthetic import synthetic_smpl_arrays
from usd_garment.body.io import default_body_path, load_body_model
from usd_garment.body.model import BodyModel


@pytest.fixture(scope="session")
def synthetic_body() -> BodyModel:
    """A 192-vertex SMPL-layout body (8 rigid vertices per joint), no file needed."""
    a = synthetic_smpl_arrays()
    return BodyModel(
        a["v_template"], a["shapedirs"], a["posedirs"], a["J_regressor"], a["weights"],
        a["f"].astype(np.int64), name="synthetic",
    )  # fmt: skip


@pytest.fixture(scope="session")
def body_model(synthetic_body: BodyModel) -> BodyModel:
    """The embedded default body when it is built, else the synthetic one."""
    return load_body_model() if default_body_path().is_file() else synthetic_body
