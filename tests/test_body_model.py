"""Body model: loading SMPL-format files, the forward pass and LBS against references."""

from __future__ import annotations

import pickle
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.synthetic import synthetic_smpl_arrays
from usd_garment.body import SMPL_JOINT_NAMES, BodyModelError, load_body_model
from usd_garment.body.io import save_body_model
from usd_garment.body.lbs import batch_rodrigues, inverse_skin, skin, solve3

J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


@pytest.fixture
def smpl_npz(tmp_path: Path) -> Path:
    path = tmp_path / "SMPL_TEST.npz"
    np.savez(path, **synthetic_smpl_arrays())
    return path


def test_rodrigues_matches_reference() -> None:
    rng = np.random.default_rng(1)
    vecs = rng.normal(size=(50, 3))
    mats = batch_rodrigues(torch.tensor(vecs)).numpy()
    for vec, mat in zip(vecs, mats, strict=True):
        angle = np.linalg.norm(vec)
        k = vec / angle
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        ref = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
        np.testing.assert_allclose(mat, ref, atol=1e-10)


def test_solve3_matches_lapack_on_blended_transforms() -> None:
    gen = torch.Generator().manual_seed(4)
    # Blends of two rotations, scaled: the skinning transforms the solve inverts.
    first = batch_rodrigues(torch.randn(200, 3, generator=gen, dtype=torch.float64))
    second = batch_rodrigues(torch.randn(200, 3, generator=gen, dtype=torch.float64))
    share = torch.rand(200, 1, 1, generator=gen, dtype=torch.float64)
    matrices = (share * first + (1 - share) * second).reshape(4, 50, 3, 3)
    rhs = torch.randn(4, 50, 3, generator=gen, dtype=torch.float64)
    ours = solve3(matrices, rhs)
    assert ours.shape == rhs.shape and ours.is_contiguous()
    np.testing.assert_allclose(ours, torch.linalg.solve(matrices, rhs[..., None])[..., 0],
                               rtol=1e-9, atol=1e-9)  # fmt: skip
    assert torch.allclose(torch.einsum("...cd,...d->...c", matrices, ours), rhs, atol=1e-9)


def test_solve3_gives_the_least_norm_solution_of_a_singular_blend() -> None:
    # Two bones turned a quarter turn either way about z, blended half and half: the blend
    # flattens x and y (det 0), where the adjugate alone divides by zero.
    turns = batch_rodrigues(torch.tensor([[0.0, 0.0, 1.5707964], [0.0, 0.0, -1.5707964]]))
    matrices = torch.stack([turns.mean(0), torch.eye(3)])  # (2, 3, 3), the second regular
    rhs = torch.tensor([[0.3, -0.2, 0.5], [0.1, 0.2, 0.3]])
    ours = solve3(matrices, rhs)
    assert torch.isfinite(ours).all()
    expected = torch.linalg.pinv(matrices[0].double()) @ rhs[0].double()
    np.testing.assert_allclose(ours[0], expected, atol=1e-5)  # (0, 0, 0.5)
    np.testing.assert_allclose(ours[1], rhs[1], atol=1e-7)


def test_inverse_skin_inverts_skin() -> None:
    gen = torch.Generator().manual_seed(5)
    transforms = torch.eye(4).repeat(2, 3, 1, 1)
    transforms[..., :3, :3] = batch_rodrigues(0.5 * torch.randn(2, 3, 3, generator=gen))
    transforms[..., :3, 3] = torch.randn(2, 3, 3, generator=gen)
    weights = torch.softmax(torch.randn(2, 40, 3, generator=gen), dim=-1)
    rest = torch.randn(2, 40, 3, generator=gen)
    posed = skin(rest, weights, transforms)
    assert torch.allclose(inverse_skin(posed, weights, transforms), rest, atol=1e-4)


def test_zero_pose_gives_template(smpl_npz: Path) -> None:
    model = load_body_model(smpl_npz)
    out = model(torch.zeros(1, 10), torch.zeros(1, 24, 3))
    np.testing.assert_allclose(out.vertices[0], model.v_template, atol=1e-6)
    trans = torch.tensor([[0.3, -0.1, 2.0]])
    moved = model(torch.zeros(1, 10), torch.zeros(1, 24, 3), trans)
    np.testing.assert_allclose(moved.vertices[0], model.v_template + trans, atol=1e-6)


def test_npz_round_trip(smpl_npz: Path, tmp_path: Path) -> None:
    model = load_body_model(smpl_npz)
    again = tmp_path / "ours.npz"
    save_body_model(again, model, name="roundtrip")
    reloaded = load_body_model(again)
    assert reloaded.name == "roundtrip"
    for key in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "faces"):
        assert torch.equal(getattr(model, key), getattr(reloaded, key)), key


def test_pkl_with_chumpy_and_sparse_regressor_loads_without_chumpy(tmp_path: Path) -> None:
    """SMPL's .pkl holds chumpy arrays and a scipy sparse regressor; we read it without chumpy."""
    scipy_sparse = pytest.importorskip("scipy.sparse")
    arrays = synthetic_smpl_arrays()
    fake = types.ModuleType("chumpy.ch")

    class Ch:  # stands for chumpy.ch.Ch, which pickles its value in the state dict as 'x'
        def __init__(self, x: np.ndarray) -> None:
            self.x = x

    Ch.__module__, Ch.__qualname__ = "chumpy.ch", "Ch"
    fake.Ch = Ch  # type: ignore[attr-defined]
    sys.modules["chumpy"] = types.ModuleType("chumpy")
    sys.modules["chumpy.ch"] = fake
    try:
        raw = dict(arrays)
        raw["shapedirs"] = Ch(arrays["shapedirs"])
        raw["J_regressor"] = scipy_sparse.csc_matrix(arrays["J_regressor"])
        path = tmp_path / "basicModel_neutral.pkl"
        path.write_bytes(pickle.dumps(raw, protocol=2))
    finally:
        del sys.modules["chumpy"], sys.modules["chumpy.ch"]
    model = load_body_model(path)
    np.testing.assert_allclose(model.shapedirs, arrays["shapedirs"], atol=1e-7)
    np.testing.assert_allclose(model.J_regressor, arrays["J_regressor"], atol=1e-7)


def test_smplh_joints_fold_onto_hands(tmp_path: Path) -> None:
    """An SMPL-H-like file with 52 joints loads as 24, finger weights moved to the hand joints."""
    arrays = synthetic_smpl_arrays()
    v = arrays["v_template"].shape[0]
    parents = list(arrays["kintree_table"][0][:22]) + [20] * 15 + [21] * 15
    weights = np.zeros((v, 52))
    weights[:, :22] = arrays["weights"][:, :22]
    weights[:, 22] = arrays["weights"][:, 22]  # left-hand cluster now on a left finger joint
    weights[:, 37] = arrays["weights"][:, 23]  # right-hand cluster on a right finger joint
    regressor = np.zeros((52, v))
    regressor[:22] = arrays["J_regressor"][:22]
    regressor[22:37] = arrays["J_regressor"][22]
    regressor[37:] = arrays["J_regressor"][23]
    arrays.update(weights=weights, J_regressor=regressor,
                  kintree_table=np.stack([parents, np.arange(52)]))  # fmt: skip
    path = tmp_path / "smplh.npz"
    np.savez(path, **arrays)
    model = load_body_model(path)
    assert model.weights.shape == (v, 24)
    np.testing.assert_allclose(model.weights.sum(1), 1.0, atol=1e-6)
    np.testing.assert_allclose(model.weights[:, 22:], synthetic_smpl_arrays()["weights"][:, 22:])


def test_amass_like_pose_moves_the_right_limbs(smpl_npz: Path) -> None:
    model = load_body_model(smpl_npz)
    pose = torch.zeros(1, 24, 3)
    pose[0, J["left_shoulder"]] = torch.tensor([0.0, 0.0, 1.2])  # raise the left arm
    pose[0, J["right_knee"]] = torch.tensor([1.5, 0.0, 0.0])  # bend the right knee
    rest = model(torch.zeros(1, 10), torch.zeros(1, 24, 3)).joints[0]
    posed = model(torch.zeros(1, 10), pose).joints[0]
    assert posed[J["left_wrist"], 1] > rest[J["left_wrist"], 1] + 0.3  # left hand goes up
    assert torch.allclose(posed[J["right_wrist"]], rest[J["right_wrist"]], atol=1e-6)
    assert posed[J["right_ankle"], 2] < rest[J["right_ankle"], 2] - 0.2  # foot goes back
    assert posed[J["right_ankle"], 1] > rest[J["right_ankle"], 1] + 0.1  # and up
    assert torch.allclose(posed[J["left_ankle"]], rest[J["left_ankle"]], atol=1e-6)


def test_forward_is_differentiable_and_batched(smpl_npz: Path) -> None:
    model = load_body_model(smpl_npz)
    pose = (0.3 * torch.randn(4, 24, 3)).requires_grad_()
    betas = torch.randn(4, 10, requires_grad=True)
    out = model(betas, pose, torch.zeros(4, 3))
    single = model(betas[2:3], pose[2:3], torch.zeros(1, 3))
    torch.testing.assert_close(out.vertices[2:3], single.vertices)
    out.vertices.square().sum().backward()
    assert pose.grad is not None and torch.isfinite(pose.grad).all()
    assert betas.grad is not None and betas.grad.abs().sum() > 0


def test_pose_blendshapes_apply(smpl_npz: Path) -> None:
    model = load_body_model(smpl_npz)
    assert model.has_pose_blendshapes
    pose = torch.zeros(1, 24, 3)
    pose[0, J["spine1"]] = torch.tensor([0.5, 0.0, 0.0])
    out = model(torch.zeros(1, 10), pose)
    assert not torch.allclose(out.rest_vertices[0], model.v_template)


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"not a numpy file", "cannot read"), (None, "no such body model file")],
)
def test_bad_body_files(tmp_path: Path, content: bytes | None, message: str) -> None:
    path = tmp_path / "model.npz"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(BodyModelError, match=message):
        load_body_model(path)


def test_wrong_layout_is_rejected(tmp_path: Path) -> None:
    arrays = synthetic_smpl_arrays()
    del arrays["weights"]
    path = tmp_path / "partial.npz"
    np.savez(path, **arrays)
    with pytest.raises(BodyModelError, match="missing weights"):
        load_body_model(path)
    arrays = synthetic_smpl_arrays()
    arrays["kintree_table"][0, 5] = 3
    np.savez(path, **arrays)
    with pytest.raises(BodyModelError, match="kinematic tree"):
        load_body_model(path)
