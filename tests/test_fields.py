"""Diffused body fields and canonical SDF: the shipped default-body grids against slow references
(the diffusion computed directly, the exact signed distance), and both fitting methods on a tiny
closed body."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
import trimesh
from click.testing import CliRunner

from usd_garment.body import BodyModel, load_body_model
from usd_garment.body.joints import NUM_JOINTS
from usd_garment.cli.main import main
from usd_garment.fields import BodyFields, load_body_fields, save_body_fields
from usd_garment.fields import grid as grid_module
from usd_garment.fields.grid import DenseGrid, SparseGrid

pytest.importorskip("warp")

from usd_garment.fields.diffusion import BodySurfaceQuery
from usd_garment.fields.evaluate import grid_vs_diffusion, near_surface_points
from usd_garment.fields.fit import FieldLevel, FitConfig, fit_body_fields, mlps_from_state


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return load_body_model()


@pytest.fixture(scope="module")
def fields() -> BodyFields:
    return load_body_fields()


def _tiny_body() -> BodyModel:
    """A closed capsule-like body along X: left half skinned to left_hip, right to right_hip,
    with random shape and pose blendshapes."""
    mesh = trimesh.creation.capsule(height=0.4, radius=0.1, count=[8, 8])
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    v = np.asarray(mesh.vertices, dtype=np.float32)
    rng = np.random.default_rng(0)
    weights = np.zeros((len(v), NUM_JOINTS), dtype=np.float32)
    left = 1.0 / (1.0 + np.exp(-v[:, 0] / 0.05))
    weights[:, 1], weights[:, 2] = left, 1.0 - left
    shapedirs = rng.normal(scale=0.01, size=(len(v), 3, 10)).astype(np.float32)
    posedirs = rng.normal(scale=0.001, size=(len(v), 3, 207)).astype(np.float32)
    regressor = np.full((NUM_JOINTS, len(v)), 1.0 / len(v), dtype=np.float32)
    return BodyModel(v, shapedirs, posedirs, regressor, weights, np.asarray(mesh.faces), "tiny")


TINY_CONFIG = FitConfig(
    samples=600,
    diffusion_samples=8,
    epochs=2,
    batch=256,
    levels=(
        FieldLevel(0.025, outside=0.04, inside=0.04, groups=("weights",)),
        FieldLevel(0.05, outside=0.1),
    ),
    coarse_field_spacing=0.2,
    sdf_spacing=0.02,
    sdf_band=0.04,
    sdf_coarse_spacing=0.05,
)


@pytest.fixture(scope="module")
def tiny() -> tuple[BodyModel, BodyFields]:
    body = _tiny_body()
    return body, fit_body_fields(body, config=TINY_CONFIG)


@pytest.fixture(scope="module")
def tiny_mlp() -> BodyFields:
    return fit_body_fields(_tiny_body(), config=TINY_CONFIG, method="mlp")


def test_weights_are_convex(fields: BodyFields) -> None:
    g = torch.Generator().manual_seed(0)
    pts = (torch.rand(2, 500, 3, generator=g) - 0.5) * torch.tensor([4.0, 4.0, 2.0])
    w = fields.weights(pts)
    assert w.shape == (2, 500, NUM_JOINTS)
    assert (w >= 0).all()
    torch.testing.assert_close(w.sum(-1), torch.ones(2, 500))


def test_weights_at_vertices_match_body(fields: BodyFields, body: BodyModel) -> None:
    # The target: mean L1 <= 0.02 at the body vertices through the shipped grid. The rest is
    # inherent to the definition (a vertex interpolates nodes a few mm off the surface, whose
    # diffused values are smoother where the surface weights change fast).
    w = fields.weights(body.v_template)
    err = (w - body.weights).abs().sum(-1)
    assert float(err.mean()) <= 0.02
    assert float(err.quantile(0.9)) < 0.08
    same = w.argmax(-1) == body.weights.argmax(-1)
    assert float(same.float().mean()) > 0.97


def test_shape_dirs_at_vertices_match_body(fields: BodyFields, body: BodyModel) -> None:
    s = fields.shape_dirs(body.v_template)
    assert s.shape == (body.num_vertices, 3, 10)
    scale = float(body.shapedirs.abs().mean())
    assert float((s - body.shapedirs).abs().mean()) < 0.05 * scale
    assert fields.pose_dirs(body.v_template[:4]) is None


def test_sdf_sign(fields: BodyFields, body: BodyModel) -> None:
    joints = body.shaped(torch.zeros(1, 10))[1][0]
    inside = joints[[0, 3, 6, 9, 12]]  # pelvis and spine joints lie inside the torso
    assert (fields.sdf(inside) < -0.02).all()
    far = torch.tensor([[3.0, 0.0, 0.0], [0.0, 0.0, -2.0], [0.0, 0.0, 0.6]])
    d = fields.sdf(far)
    assert (d > 0.3).all()
    exact = BodySurfaceQuery(body.v_template.numpy(), body.faces.numpy()).signed_distance(
        far.numpy()
    )
    assert (d.numpy() >= exact - 1e-3).all()  # conservative beyond the grid


def test_sdf_matches_exact(fields: BodyFields, body: BodyModel) -> None:
    pts = near_surface_points(body, 3000, seed=5)
    exact = BodySurfaceQuery(body.v_template.numpy(), body.faces.numpy()).signed_distance(pts)
    err = np.abs(fields.sdf(torch.from_numpy(pts)).numpy() - exact)
    assert err.mean() < 5e-4
    assert err.max() < 5e-3
    clear = np.abs(exact) > 0.003
    assert (
        np.sign(fields.sdf(torch.from_numpy(pts[clear])).numpy()) == np.sign(exact[clear])
    ).all()


def test_grid_matches_diffusion(fields: BodyFields, body: BodyModel) -> None:
    # Reference: the paper's diffusion (N = 256) computed directly at random points within 3 cm
    # of the surface; the gap includes the reference's own Monte Carlo noise.
    assert fields.mlp_state is None and fields.config["method"] == "direct"
    g = grid_vs_diffusion(fields, body, count=1500, seed=6)
    assert g["weights_mean_l1"] < 0.03
    assert g["weights_p99_l1"] < 0.25
    assert g["shape_dirs_mean_abs_m"] < 0.05 * float(body.shapedirs.abs().mean())


def test_gradients_flow_to_points(fields: BodyFields, body: BodyModel) -> None:
    pts = torch.from_numpy(near_surface_points(body, 200, seed=7)).requires_grad_(True)
    w, s, _ = fields.all_fields(pts)
    loss = (w * torch.arange(NUM_JOINTS)).sum() + s.sum() + fields.sdf(pts).sum()
    loss.backward()
    assert pts.grad is not None and torch.isfinite(pts.grad).all()
    assert float(pts.grad.abs().sum()) > 0
    # The SDF's gradient is a unit normal, roughly.
    p = pts.detach().clone().requires_grad_(True)
    fields.sdf(p).sum().backward()
    assert float((p.grad.norm(dim=-1) - 1).abs().median()) < 0.05


def test_single_channel_gradient_is_torchs_own_to_the_bit(
    fields: BodyFields, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The SDF's gradient in the points goes through a gather of the corner values
    # (``_SingleChannelGather``) instead of embedding_bag's own backward: the same values.
    g = torch.Generator().manual_seed(3)
    box = torch.tensor(fields.sdf_fine.shape) * fields.sdf_fine.spacing
    pts = fields.sdf_fine.origin + box * (0.05 + 0.9 * torch.rand(5000, 3, generator=g))
    grad = torch.rand(5000, generator=g)
    calls: list[int] = []
    gather = grid_module._SingleChannelGather.apply

    def counted(*args: torch.Tensor) -> torch.Tensor:
        calls.append(len(args[0]))
        return gather(*args)

    monkeypatch.setattr(grid_module._SingleChannelGather, "apply", counted)
    p = pts.clone().requires_grad_(True)
    (ours,) = torch.autograd.grad(fields.sdf(p), p, grad)
    assert calls and calls[0] == 5000
    monkeypatch.setattr(
        grid_module,
        "_interpolate",
        lambda w, table, rows: F.embedding_bag(rows, table, per_sample_weights=w, mode="sum"),
    )
    (torchs,) = torch.autograd.grad(fields.sdf(p), p, grad)
    assert float(ours.abs().sum()) > 0
    assert torch.equal(ours, torchs)


def test_dense_grid_matches_grid_sample() -> None:
    g = torch.Generator().manual_seed(0)
    values = torch.rand(5, 6, 7, 4, generator=g)
    grid = DenseGrid(torch.tensor([-1.0, -0.5, 0.2]), 0.1, {"v": values})
    pts = grid.origin + torch.rand(300, 3, generator=g) * (grid.upper - grid.origin)
    norm = (pts - grid.origin) / (grid.upper - grid.origin) * 2 - 1
    vol = values.permute(3, 2, 1, 0)[None]  # (1, C, z, y, x)
    ref = F.grid_sample(vol, norm[None, :, None, None, :], align_corners=True)[0, :, :, 0, 0].T
    torch.testing.assert_close(grid(pts, ("v",))[0], ref)
    mask = torch.ones(5, 6, 7, dtype=torch.bool)
    sparse = SparseGrid(grid.origin, 0.1, mask, {"v": values.reshape(-1, 4)})
    out, valid = sparse(pts, ("v",))
    assert valid.all()
    torch.testing.assert_close(out[0], ref)


def test_sparse_grid_reads_valid_in_the_box_with_every_corner_in_the_band() -> None:
    """A point reads valid where it lies in the lattice box (on its faces too) and all eight
    corners of its cell hold values: not beyond a face, not NaN, not in a cell with a node
    outside the band."""
    values = torch.rand(5, 6, 7, 2, generator=torch.Generator().manual_seed(1))
    mask = torch.ones(5, 6, 7, dtype=torch.bool)
    mask[4, 5, 6] = False
    grid = SparseGrid(torch.zeros(3), 0.125, mask, {"v": values[mask]})
    pts = torch.tensor(
        [
            [0.0, 0.0, 0.0],  # a corner of the box
            [0.5, 0.3, 0.4],  # on the upper x face
            [0.51, 0.3, 0.4],  # beyond it
            [-0.01, 0.3, 0.4],  # below the lower x face
            [0.45, 0.6, 0.7],  # in a cell with the unmasked node
            [float("nan"), 0.3, 0.4],
        ]
    )
    out, valid = grid(pts, ("v",))
    assert valid.tolist() == [True, True, False, False, False, False]
    torch.testing.assert_close(out[0][0], values[0, 0, 0])


def test_a_nan_point_reads_invalid_on_a_lattice_of_odd_sizes() -> None:
    """A NaN point's cell is in range whatever the lattice's sizes (its integer cast wrapped to
    an index out of range on odd ones): the sparse grid reads it invalid, the dense one NaN."""
    values = torch.rand(5, 7, 9, 2, generator=torch.Generator().manual_seed(2))
    mask = torch.ones(5, 7, 9, dtype=torch.bool)
    pts = torch.tensor([[float("nan"), 0.3, 0.4], [0.25, 0.375, 0.5]])
    out, valid = SparseGrid(torch.zeros(3), 0.125, mask, {"v": values[mask]})(pts, ("v",))
    assert valid.tolist() == [False, True]
    torch.testing.assert_close(out[0][1], values[2, 3, 4])
    (dense,) = DenseGrid(torch.zeros(3), 0.125, {"v": values})(pts, ("v",))
    assert dense[0].isnan().all()
    torch.testing.assert_close(dense[1], values[2, 3, 4])


def test_diffusion_at_surface_is_the_surface_value() -> None:
    body = _tiny_body()
    query = BodySurfaceQuery(body.v_template.numpy(), body.faces.numpy())
    idx = np.arange(0, body.num_vertices, 7)
    op = query.diffusion_matrix(body.v_template.numpy()[idx], 16, np.random.default_rng(0))
    np.testing.assert_allclose(op.toarray()[np.arange(len(idx)), idx], 1.0, atol=1e-5)
    # Off the surface, rows average many surface points and still sum to 1.
    far = body.v_template.numpy()[idx] * 1.5
    op = query.diffusion_matrix(far, 64, np.random.default_rng(0))
    np.testing.assert_allclose(np.asarray(op.sum(1)).ravel(), 1.0, atol=1e-5)
    assert (np.diff(op.indptr) > 3).all()


def test_tiny_fit_and_round_trip(tiny: tuple[BodyModel, BodyFields], tmp_path: Path) -> None:
    body, fitted = tiny
    assert fitted.mlp_state is None
    assert [level.names for level in fitted.field_levels] == [
        ("weights",),
        ("weights", "shape_dirs", "pose_dirs"),
    ]
    pts = body.v_template[:50]
    w, s, p = fitted.all_fields(pts)
    assert w.shape == (50, NUM_JOINTS) and s.shape == (50, 3, 10)
    assert p is not None and p.shape == (50, 3, 207)
    torch.testing.assert_close(w.sum(-1), torch.ones(50))
    assert (fitted.sdf(torch.zeros(1, 3)) < -0.05).all()
    path = tmp_path / "tiny_fields.npz"
    save_body_fields(path, fitted)
    loaded = load_body_fields(path)
    assert loaded.body_name == "tiny" and loaded.config["method"] == "direct"
    assert "samples" not in loaded.config  # an mlp-only setting
    torch.testing.assert_close(loaded.weights(pts), w, atol=2e-3, rtol=0)
    torch.testing.assert_close(loaded.pose_dirs(pts), p, atol=1e-5, rtol=1e-2)
    torch.testing.assert_close(loaded.sdf(pts), fitted.sdf(pts), atol=1e-4, rtol=0)
    save_body_fields(tmp_path / "again.npz", loaded)
    again = load_body_fields(tmp_path / "again.npz")
    torch.testing.assert_close(again.shape_dirs(pts), loaded.shape_dirs(pts))


def test_cli_info(tmp_path: Path) -> None:
    runner = CliRunner()
    result = runner.invoke(main, ["fields", "info", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["pose_dirs"] is False and not summary["has_mlp"]
    assert summary["field_levels"][0]["groups"] == ["weights"]
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    result = runner.invoke(main, ["fields", "info", str(bad)])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert "cannot read body fields" in result.output


def test_tiny_mlp_fit(tiny_mlp: BodyFields, tmp_path: Path) -> None:
    fitted = tiny_mlp
    assert fitted.mlp_state is not None and fitted.config["samples"] == TINY_CONFIG.samples
    path = tmp_path / "tiny_mlp.npz"
    save_body_fields(path, fitted)
    mlps = mlps_from_state(load_body_fields(path).mlp_state or {})
    assert set(mlps) == {"weights", "shape_dirs", "pose_dirs"}
    # The baked grid reproduces its MLP at nodes of the finest weights level.
    finest = fitted.field_levels[0]
    nodes = finest.origin + finest.spacing * finest.mask.nonzero()[:40].float()
    interior = finest(nodes, ("weights",))[1]
    assert interior.any()
    w = fitted.weights(nodes[interior])
    gap = (w - mlps["weights"].evaluate(nodes[interior])).abs().sum(-1)
    assert float(gap.max()) < 0.02  # the 5e-4 weight floor


def test_diffuse_is_the_diffusion_operator() -> None:
    body = _tiny_body()
    query = BodySurfaceQuery(body.v_template.numpy(), body.faces.numpy())
    pts = body.v_template.numpy()[::5] * 1.3
    values = body.weights.numpy()
    op = query.diffusion_matrix(pts, 32, np.random.default_rng(3))
    out = query.diffuse(pts, values, 32, np.random.default_rng(3), chunk=len(pts))
    np.testing.assert_allclose(out, op @ values, atol=1e-6)


def test_fit_rejects_unknown_method() -> None:
    with pytest.raises(ValueError, match="unknown fitting method"):
        fit_body_fields(_tiny_body(), config=TINY_CONFIG, method="spline")


def test_levels_blend_without_seams() -> None:
    # A band holding 1 (x < 0.9 m) over a coarse grid holding 0: the value ramps over the band's
    # outermost cell instead of jumping where the band ends.
    shape = (20, 4, 4)
    mask = torch.zeros(shape, dtype=torch.bool)
    mask[:10] = True
    origin = torch.zeros(3)
    count = int(mask.sum())
    ones = {"weights": torch.ones(count, NUM_JOINTS), "shape_dirs": torch.ones(count, 30)}
    zeros = {"weights": torch.ones(*shape, NUM_JOINTS), "shape_dirs": torch.zeros(*shape, 30)}
    sdf = {"sdf": torch.zeros(*shape, 1)}
    fields = BodyFields(
        [SparseGrid(origin, 0.1, mask, ones)],
        DenseGrid(origin, 0.1, zeros),
        SparseGrid(origin, 0.1, mask, {"sdf": torch.zeros(count, 1)}),
        DenseGrid(origin, 0.1, sdf),
        "blocks",
    )
    x = torch.linspace(0.12, 1.5, 1381)
    pts = torch.stack([x, torch.full_like(x, 0.15), torch.full_like(x, 0.15)], dim=1)
    s = fields.shape_dirs(pts)[:, 0, 0]
    assert float(s[x < 0.79].min()) > 1 - 1e-5 and float(s[x > 0.91].abs().max()) < 1e-5
    assert float(s.diff().abs().max()) < 0.011  # 1 mm steps across a 10 cm ramp


def test_linearized_fields_agree_with_the_lookup_near_the_anchor() -> None:
    from usd_garment.garment.library import load_template

    fields = load_body_fields()
    anchor = torch.as_tensor(load_template("tshirt", "low").vertices)
    gen = torch.Generator().manual_seed(0)
    near = anchor + 2e-3 * torch.randn(3, *anchor.shape, generator=gen)  # ~3.5 mm away
    far = anchor.clone().expand(2, -1, -1).clone()
    far[:, :10] += 0.05  # 5 cm: beyond the radius, looked up exactly
    tangent = fields.linearized(anchor)
    # Near: first order (skinning weights can turn within millimetres next to the body, so a
    # few per cent at worst, a thousandth on average); far: the exact lookup itself.
    for points, worst, mean in ((near, 0.03, 1e-3), (far, 1e-6, 1e-6)):
        exact, approx = fields.all_fields(points), tangent.all_fields(points)
        for a, b in zip(exact[:2], approx[:2], strict=True):
            gap = (a - b).abs()
            assert float(gap.max()) < worst and float(gap.mean()) < mean
    w = tangent.all_fields(near)[0]
    assert bool((w >= 0).all()) and torch.allclose(w.sum(-1), torch.ones(()), atol=1e-5)


def test_tangent_of_one_shape_is_the_tangent_contracted_with_its_betas() -> None:
    from usd_garment.garment.library import load_template

    fields = load_body_fields()
    anchor = torch.as_tensor(load_template("tshirt", "low").vertices)
    gen = torch.Generator().manual_seed(1)
    points = anchor + 4e-3 * torch.randn(2, *anchor.shape, generator=gen)
    points[:, :5] += 0.05  # beyond the radius: the exact lookup
    betas = torch.randn(10, generator=gen)
    tangent = fields.linearized(anchor)
    weights, offsets = tangent.shaped(points, betas)
    all_weights, shape_dirs, _ = tangent.all_fields(points)
    assert torch.allclose(weights, all_weights, atol=1e-6)
    assert torch.allclose(offsets, torch.einsum("bnck,k->bnc", shape_dirs, betas), atol=1e-6)


def test_lookup_of_one_shape_is_the_lookup_contracted_with_its_betas(
    body: BodyModel, fields: BodyFields
) -> None:
    gen = torch.Generator().manual_seed(2)
    rest = body.shaped(torch.zeros(1, 10))[0][0]
    # Near the skin (finest bands), farther out (coarser bands, the dense grid) and past the box.
    scales = torch.tensor([0.005, 0.03, 0.1, 0.4, 1.5])[:, None, None]
    points = rest + scales * torch.randn(len(scales), *rest.shape, generator=gen)
    betas = 2 * torch.randn(10, generator=gen)
    weights, offsets = fields.shaped(points, betas)
    all_weights, shape_dirs, _ = fields.all_fields(points)
    assert torch.allclose(weights, all_weights, atol=1e-6)
    assert torch.allclose(offsets, torch.einsum("bnck,k->bnc", shape_dirs, betas), atol=1e-6)
    # The grids contracted for the last shape are kept: another shape gets its own, the first
    # shape again gets the same values, and a shape that needs gradients gets them.
    other = fields.shaped(points, -betas)[1]
    assert torch.allclose(other, torch.einsum("bnck,k->bnc", shape_dirs, -betas), atol=1e-6)
    assert torch.equal(fields.shaped(points, betas)[1], offsets)
    wanting = betas.clone().requires_grad_(True)
    fields.shaped(points, wanting)[1].sum().backward()
    assert wanting.grad is not None
    assert torch.allclose(wanting.grad, shape_dirs.sum(dim=(0, 1, 2)), rtol=1e-4, atol=1e-4)


def test_template_shape_has_no_offsets_and_looks_nothing_up(
    body: BodyModel, fields: BodyFields, monkeypatch: pytest.MonkeyPatch
) -> None:
    gen = torch.Generator().manual_seed(3)
    rest = body.shaped(torch.zeros(1, 10))[0][0]
    points = rest + 0.03 * torch.randn(2, *rest.shape, generator=gen)
    zero = torch.zeros(10)
    # What the lookup gives for β = 0: the blendshapes contracted with zeros, exactly zero.
    levels, coarse = fields._offset_grids(zero)
    (looked_up,) = fields._cascade(points.reshape(-1, 3), ("offset",), levels, coarse)
    assert torch.equal(looked_up, torch.zeros_like(looked_up))

    def no_lookup(*args: object, **kwargs: object) -> None:
        raise AssertionError("the offsets of the template shape were looked up")

    monkeypatch.setattr(fields, "_offset_grids", no_lookup)
    offsets = fields.shape_offsets(points, zero)
    assert offsets.shape == points.shape and torch.equal(offsets, torch.zeros_like(points))
    weights, shaped_offsets = fields.shaped(points, zero)
    assert torch.equal(shaped_offsets, offsets)
    assert torch.allclose(weights, fields.weights(points))
