"""The body layer that ``import-amass`` and ``motion make`` write: USD's own skinning of its mesh
(``UsdSkel``) gives, at every frame, the body the project poses with its own LBS, so the body a
user sees is the body the garment avoids."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from pxr import Usd, UsdGeom, UsdSkel

from tests.test_amass import _amass_npz
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.motion.amass import load_amass
from usd_garment.motion.procedural import make_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.body_layer import (
    MESH_PATH,
    SKEL_ROOT_PATH,
    SKELETON_PATH,
    all_weights,
    write_body_layer,
)

#: Largest allowed distance (m) between USD's skinned mesh and the body model's vertices.
TOLERANCE_M = 1e-4


def _without_pose_blendshapes(body: BodyModel) -> BodyModel:
    """``body`` without pose correctives, which UsdSkel skinning cannot express (the embedded
    default body has none; the synthetic test body, used when it is not built, has some)."""
    if not body.has_pose_blendshapes:
        return body
    return BodyModel(
        body.v_template.numpy(), body.shapedirs.numpy(), np.zeros((body.num_vertices, 3, 0)),
        body.J_regressor.numpy(), body.weights.numpy(), body.faces.numpy(), name=body.name,
    )  # fmt: skip


def usd_skinned_points(path: Path, time_codes: np.ndarray) -> np.ndarray:
    """World-space points ``(T, V, 3)`` (stage units) of the body mesh of a body layer, skinned
    by ``UsdSkel`` at each time code, the mesh's local-to-world transform applied."""
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetPrimAtPath(SKEL_ROOT_PATH)), Usd.PrimDefaultPredicate)
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath(SKELETON_PATH)))
    mesh = stage.GetPrimAtPath(MESH_PATH)
    skin_query = cache.GetSkinningQuery(mesh)
    assert skel_query and skin_query
    xforms = UsdGeom.XformCache()
    out = []
    for code in time_codes:
        time = Usd.TimeCode(float(code))
        points = mesh.GetAttribute("points").Get(time)
        transforms = skel_query.ComputeSkinningTransforms(time)
        assert skin_query.ComputeSkinnedPoints(transforms, points, time)
        xforms.SetTime(time)
        to_world = np.array(xforms.GetLocalToWorldTransform(mesh), dtype=np.float64)
        p = np.array(points, dtype=np.float64)
        out.append(p @ to_world[:3, :3] + to_world[3, :3])
    return np.stack(out)


def _max_distance(path: Path, motion: SmplMotion, body: BodyModel) -> float:
    """Largest distance (m) over all vertices and frames between USD's skinning of the layer at
    ``path`` and ``body``'s LBS of ``motion``."""
    with torch.no_grad():
        expected = body(
            torch.as_tensor(motion.betas), torch.as_tensor(motion.pose),
            torch.as_tensor(motion.trans),
        ).vertices.double().numpy()  # fmt: skip
    skinned = usd_skinned_points(path, motion.time_codes)
    assert skinned.shape == expected.shape
    return float(np.linalg.norm(skinned - expected, axis=-1).max())


@pytest.mark.parametrize("kind", ["walk", "amass"])
def test_usd_skinning_is_the_body_model(tmp_path: Path, body_model: BodyModel, kind: str) -> None:
    """A whole motion: a 60-frame procedural walk with a non-average shape, and an AMASS-like
    Z-up file (turn, arm raise, knee bend, betas from −1 to 1) imported as ``import-amass`` does."""
    if kind == "walk":
        betas = np.linspace(-1.5, 1.5, 10)
        motion = make_motion("walk", 60, seed=3, betas=betas, body=body_model)
    else:
        _amass_npz(tmp_path / "a.npz", frames=40)
        motion = load_amass(tmp_path / "a.npz", body_model)
    assert np.abs(motion.betas).max() > 0.5
    path = tmp_path / f"{kind}.usdc"
    write_body_layer(path, motion, body_model)
    distance = _max_distance(path, motion, _without_pose_blendshapes(body_model))
    assert distance < TOLERANCE_M, f"USD skinning is {distance * 1e3:.3f} mm off the body model"


def test_every_influence_is_written(tmp_path: Path, body_model: BodyModel) -> None:
    """The mesh carries every non-zero weight of the body, padded with joint 0 / weight 0."""
    path = tmp_path / "body.usda"
    write_body_layer(path, make_motion("squat", 2, body=body_model), body_model)
    stage = Usd.Stage.Open(str(path))
    mesh = UsdSkel.BindingAPI(stage.GetPrimAtPath(MESH_PATH))
    weights = body_model.weights.numpy()
    size = int((weights != 0).sum(axis=1).max())
    assert mesh.GetJointWeightsPrimvar().GetElementSize() == size
    assert mesh.GetJointIndicesPrimvar().GetElementSize() == size
    idx = np.array(mesh.GetJointIndicesPrimvar().Get()).reshape(-1, size)
    w = np.array(mesh.GetJointWeightsPrimvar().Get()).reshape(-1, size)
    dense = np.zeros_like(weights)
    np.add.at(dense, (np.arange(len(idx))[:, None], idx), w)
    np.testing.assert_allclose(dense, weights, atol=1e-7)


def test_all_weights_pads_with_zero() -> None:
    weights = np.array([[0.0, 0.7, 0.3, 0.0], [1.0, 0.0, 0.0, 0.0], [0.1, 0.2, 0.3, 0.4]])
    idx, w = all_weights(weights)
    assert idx.dtype == np.int32 and w.dtype == np.float32 and idx.shape == w.shape == (3, 4)
    np.testing.assert_array_equal(idx[0], [1, 2, 0, 0])
    np.testing.assert_allclose(w[0], [0.7, 0.3, 0.0, 0.0])
    np.testing.assert_array_equal(idx[1], [0, 0, 0, 0])
    np.testing.assert_allclose(w[1], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(idx[2], [3, 2, 1, 0])
    idx, w = all_weights(np.eye(3))
    assert idx.shape == (3, 1) and idx[:, 0].tolist() == [0, 1, 2]


def test_betas_beyond_the_shape_space_are_not_written(
    tmp_path: Path, body_model: BodyModel
) -> None:
    """The writer refuses betas the reader would refuse, so every layer it writes reads back."""
    motion = make_motion("squat", 2, body=body_model)
    motion.betas[3] = -6.0
    path = tmp_path / "body.usda"
    with pytest.raises(ValueError, match=r"body\.usda: betas\[3\] = -6 is outside"):
        write_body_layer(path, motion, body_model)
    assert not path.exists()
    result = CliRunner().invoke(
        main, ["motion", "make", "squat", "-o", str(path), "--frames", "2", "--betas", "0,0,6"]
    )
    assert result.exit_code == 1 and not path.exists()
    assert result.stderr.strip() == (
        f"Error: {path}: betas[2] = 6 is outside the body's shape space (|beta| <= 5)"
    )
