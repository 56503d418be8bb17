"""The garment model M_G (Eqs. 8–9): identity at rest, equal to plain LBS when its fields are the
template's constant nearest-vertex values, differentiable."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from usd_garment.body.io import load_body_model
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.garment.model import GarmentModel
from usd_garment.methods.lbs import LbsMethod, nearest_body_vertex
from usd_garment.motion.sequence import SmplMotion


@pytest.fixture(scope="module")
def body():
    return load_body_model()


@pytest.fixture(scope="module")
def model(body):
    return GarmentModel(body, load_body_fields())


@pytest.fixture(scope="module")
def template():
    return load_template("tshirt", "low")


def _random_pose(frames: int, seed: int, scale: float = 0.3) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed)
    return scale * torch.randn(frames, 24, 3, generator=gen)


class ConstantFields(torch.nn.Module):
    """Fields that return, for the i-th of N points, the values of body vertex ``index[i]``."""

    def __init__(self, body, index: np.ndarray) -> None:
        super().__init__()
        self.index = torch.as_tensor(index)
        self.body = body

    def all_fields(self, points: torch.Tensor):
        lead = points.shape[:-2]
        w = self.body.weights[self.index].expand(*lead, -1, -1)
        s = self.body.shapedirs[self.index].expand(*lead, -1, -1, -1)
        return w, s, None


def test_rest_pose_and_mean_shape_return_x(model, template):
    x = torch.as_tensor(template.vertices)[None].repeat(2, 1, 1)
    x[1] += 0.01 * torch.randn_like(x[1])
    out = model(x, torch.zeros(2, 10), torch.zeros(2, 24, 3), torch.zeros(2, 3))
    torch.testing.assert_close(out.vertices, x, atol=1e-6, rtol=0)
    torch.testing.assert_close(out.unposed, x, atol=1e-6, rtol=0)
    torch.testing.assert_close(out.weights.sum(-1), torch.ones(2, x.shape[1]))


def test_constant_weights_equal_plain_lbs_of_the_template(body, template):
    model = GarmentModel(body, ConstantFields(body, nearest_body_vertex(body, template)))
    frames = 3
    pose = _random_pose(frames, seed=1)
    trans = torch.tensor([[0.0, 0.0, 0.0], [0.1, 0.2, -0.3], [1.0, 0.0, 2.0]])
    betas = torch.linspace(-1.5, 1.5, 10)
    x = torch.as_tensor(template.vertices)[None].expand(frames, -1, -1)
    ours = model(x, betas, pose, trans).vertices.numpy()
    motion = SmplMotion(betas.numpy(), pose.numpy(), trans.numpy(), fps=30.0)
    reference = LbsMethod().predict(motion, body, template)
    np.testing.assert_allclose(ours, reference, atol=2e-6)


def test_translation_is_added_after_skinning(model, template):
    x = torch.as_tensor(template.vertices)[None]
    pose, betas = _random_pose(1, seed=2), torch.full((1, 10), 0.5)
    shift = torch.tensor([[0.3, -0.2, 1.0]])
    moved = model(x, betas, pose, shift).vertices
    torch.testing.assert_close(moved, model(x, betas, pose).vertices + shift[:, None])


def test_gradients_flow_to_x_betas_and_pose(model, template):
    x = torch.as_tensor(template.vertices)[None].repeat(2, 1, 1).requires_grad_(True)
    betas = torch.zeros(2, 10).requires_grad_(True)
    pose = _random_pose(2, seed=3).requires_grad_(True)
    out = model(x, betas, pose, torch.zeros(2, 3))
    (out.vertices.square().sum() + out.unposed.square().sum()).backward()
    for grad in (x.grad, betas.grad, pose.grad):
        assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu(body, template):
    fields = load_body_fields()
    cpu = GarmentModel(body, fields)
    x = torch.as_tensor(template.vertices)[None].repeat(2, 1, 1)
    pose, betas = _random_pose(2, seed=4), torch.full((2, 10), 0.3)
    expected = cpu(x, betas, pose).vertices
    gpu = GarmentModel(load_body_model().cuda(), load_body_fields().cuda())
    got = gpu(x.cuda(), betas.cuda(), pose.cuda()).vertices.cpu()
    torch.testing.assert_close(got, expected, atol=1e-5, rtol=0)
