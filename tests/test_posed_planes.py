"""The posed collision planes pulled back to canonical space, and the regressor's L_posed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from usd_garment.body.io import load_body_model
from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.garment.model import GarmentModel
from usd_garment.training.posed_planes import (
    PLANE_RADIUS,
    PosedPlanes,
    posed_planes,
    reusable_posed_planes,
    save_posed_planes,
)


def _tshirt_set(frames: int = 3) -> CanonicalSet:
    """The low T-shirt on the default body: a rest frame and frames with the arms lowered."""
    template = load_template("tshirt", "low")
    pose = np.zeros((frames, 24, 3), np.float32)
    for t in range(1, frames):  # shoulders (SMPL 16, 17) brought down towards the sides
        pose[t, 16, 2], pose[t, 17, 2] = -0.4 * t, 0.4 * t
    x = np.repeat(template.vertices[None].astype(np.float32), frames, axis=0)
    return CanonicalSet(
        canonical=x,
        frame_offsets=np.array([0, frames], np.int64),
        betas=np.zeros((1, 10), np.float32),
        pose=pose,
        trans=np.zeros((frames, 3), np.float32),
        fps=np.array([30.0], np.float32),
        error=np.zeros(frames, np.float32),
        max_error=np.zeros(frames, np.float32),
        template=template.vertices.astype(np.float32),
        faces=template.faces.astype(np.int32),
        sources=["rest"],
        splits=["train"],
    )


def test_planes_give_the_posed_distance_at_the_target_and_to_first_order_nearby() -> None:
    body, fields = load_body_model(), load_body_fields()
    data = _tshirt_set()
    planes = posed_planes(data, body, fields, radius=0.013)
    frames = torch.arange(3)
    x = torch.as_tensor(data.canonical)
    model = GarmentModel(body, fields)
    pose = torch.as_tensor(data.pose)
    with torch.no_grad():
        art = model.articulation(torch.zeros(10), pose, torch.zeros(3, 3))
        posed = model.pose(x, art).vertices
        body_vertices = body(torch.zeros(10), pose).vertices
    query = signed_distance(
        posed, body_vertices, BodySurface(body.faces.numpy(), body.num_vertices)
    )
    valid = planes.valid.numpy()
    assert valid.any() and not valid.all()  # the garment's far vertices get no plane
    assert not valid[np.abs(query.distance) >= 0.013].any()
    d = planes.distance(frames, x).numpy()
    # the plane through the closest point: its distance along the pseudo-normal, never beyond
    assert (d[valid] <= np.abs(query.distance[valid]) + 1e-5).all()
    assert np.mean(np.abs(d[valid] - query.distance[valid]) < 1e-4) > 0.9
    # a canonical step maps to the posed step along n, to first order (the fields frozen)
    step = 1e-3 * torch.nn.functional.normalize(
        torch.randn(x.shape, generator=torch.Generator().manual_seed(0)), dim=-1
    )
    with torch.no_grad():
        moved = model.pose(x + step, art).vertices
    n = torch.as_tensor(query.normal, dtype=torch.float32)
    posed_change = ((moved - posed) * n).sum(-1).numpy()
    plane_change = (planes.distance(frames, x + step) - planes.distance(frames, x)).numpy()
    error = np.abs(plane_change[valid] - posed_change[valid])
    # exact where the skinning weights are flat; the weights' slope near joints costs a little
    assert np.median(error) < 1e-5 and np.percentile(error, 90) < 1e-4  # of a 1 mm step


def test_plane_loss_and_inside() -> None:
    planes = PosedPlanes(
        normal=torch.tensor([[[1.0, 0, 0], [0, 1.0, 0]]]),
        offset=torch.tensor([[0.0, -0.01]]),
        valid=torch.tensor([[True, False]]),
    )
    x = torch.tensor([[[-0.003, 0, 0], [0, 0, 0]]])
    frames = torch.tensor([0])
    assert float(planes.loss(frames, x, 0.002)) == pytest.approx(0.005)  # ε − (−3 mm)
    assert planes.inside(frames, x).tolist() == [[True, False]]  # no plane: never inside
    assert float(planes.loss(frames, x + torch.tensor([0.01, 0, 0]), 0.002)) == 0.0


def test_planes_are_saved_and_read_back_for_their_own_set_only(tmp_path: Path) -> None:
    data = _tshirt_set(2)
    planes = posed_planes(data, load_body_model(), load_body_fields(), radius=0.013)
    path = tmp_path / "planes.npz"
    save_posed_planes(path, planes, data, 0.013)
    back, sequences = reusable_posed_planes(path, data, 0.013)
    assert sequences == data.num_sequences
    for a, b in ((planes.normal, back.normal), (planes.offset, back.offset)):
        torch.testing.assert_close(a, b)
    assert torch.equal(planes.valid, back.valid)
    with pytest.raises(ValueError, match="another training set"):
        reusable_posed_planes(path, data, 0.02)  # another radius
    data.pose[1, 16, 2] += 0.1
    with pytest.raises(ValueError, match="another training set"):
        reusable_posed_planes(path, data, 0.013)


def test_the_planes_of_a_set_that_grew_are_kept_for_its_first_sequences(tmp_path: Path) -> None:
    """A set with a sequence appended (``project --update``): the planes saved for the set it
    grew from are its first sequence's (found by :func:`reusable_posed_planes`), the new
    sequence's are computed, and the whole equals the planes computed afresh; ``train
    regressor --planes`` does so and writes the grown set's planes over the file."""
    from usd_garment.canonical.dataset import concat_canonical_sets
    from usd_garment.cli.train import _posed_planes

    body, fields = load_body_model(), load_body_fields()
    first = _tshirt_set(2)
    second = _tshirt_set(3)
    second.pose[:, 18, 1] = 0.3  # another motion
    grown = concat_canonical_sets(first, second)
    path = tmp_path / "planes.npz"
    save_posed_planes(path, posed_planes(first, body, fields), first, PLANE_RADIUS)
    known, sequences = reusable_posed_planes(path, grown, PLANE_RADIUS)
    assert sequences == 1 and len(known.valid) == 2
    with pytest.raises(ValueError, match="another training set"):
        reusable_posed_planes(path, second, PLANE_RADIUS)  # not its beginning
    fresh = posed_planes(grown, body, fields)
    planes = _posed_planes(grown, body, fields, path)
    for a, b in ((planes.normal, fresh.normal), (planes.offset, fresh.offset)):
        torch.testing.assert_close(a, b)
    assert torch.equal(planes.valid, fresh.valid) and bool(fresh.valid[2:].any())
    assert reusable_posed_planes(path, grown, PLANE_RADIUS)[1] == 2
    with pytest.raises(ValueError, match="another training set"):
        _posed_planes(second, body, fields, path)
