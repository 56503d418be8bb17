"""Garment templates: the committed files for the default body, the recipe on a fresh build, and
the surface-nets extraction they rest on."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from usd_garment.body import default_body_path, load_body_model
from usd_garment.body.fingerprint import rest_fingerprint
from usd_garment.cli.main import main
from usd_garment.garment.hull import Grid, inside_mesh, points_inside
from usd_garment.garment.library import (
    load_template,
    read_template,
    template_dir,
    template_filename,
)
from usd_garment.garment.mesh_ops import (
    boundary_loops,
    edge_face_counts,
    face_components,
    is_manifold,
)
from usd_garment.garment.summary import clearance
from usd_garment.garment.surface_nets import surface_nets
from usd_garment.garment.template import GARMENT_NAMES, LODS, RECIPE_VERSION, GarmentTemplate
from usd_garment.garment.templates import recipe, rest_body

CASES = [(name, lod) for name in GARMENT_NAMES for lod in LODS]


@pytest.fixture(scope="module")
def body():
    return load_body_model()


@pytest.fixture(scope="module")
def rest(body):
    return rest_body(body)


def check_template(t: GarmentTemplate, rest: tuple) -> None:
    """The template is a sound garment around the rest body ``rest`` (see ``rest_body``)."""
    v, f = t.vertices.astype(np.float64), t.faces.astype(np.int64)
    assert v.shape[1] == 3 and f.shape[1] == 3 and t.uvs.shape == (len(v), 2)
    # 2-manifold, one piece, consistently oriented
    _, counts = edge_face_counts(f)
    assert counts.max() <= 2
    assert is_manifold(f)
    assert len(np.unique(face_components(f, len(v)))) == 1
    directed = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len(np.unique(directed, axis=0)) == len(directed)
    assert len(np.unique(f)) == len(v)
    # one boundary loop per opening, lying on that opening's plane
    body_v, body_f, joints, _ = rest
    planes = recipe(t.name, joints).planes
    loops = boundary_loops(f)
    assert len(loops) == len(planes) == 4
    matched = set()
    for loop in loops:
        off = [np.abs((v[loop] - p.point) @ p.normal).max() for p in planes]
        assert min(off) < 0.005
        matched.add(int(np.argmin(off)))
    assert matched == set(range(len(planes)))
    # outside the body, with normals pointing away from it
    sd, closest = clearance(v, body_v, body_f)
    assert sd.min() > 0.005
    tri = trimesh.Trimesh(v, f, process=False)
    assert ((tri.vertex_normals * (v - closest)).sum(1) > 0).mean() > 0.99
    # size and UVs
    assert abs(len(v) - LODS[t.lod]) <= 0.1 * LODS[t.lod]
    assert t.uvs.min() >= 0.0 and t.uvs.max() <= 1.0


@pytest.mark.parametrize(("name", "lod"), CASES)
def test_committed_template(name: str, lod: str, body, rest) -> None:
    template, provenance = read_template(template_dir() / template_filename(name, lod))
    assert (template.name, template.lod) == (name, lod)
    assert template.vertices.dtype == np.float32 and template.faces.dtype == np.int32
    assert provenance.recipe_version == RECIPE_VERSION
    assert provenance.body_fingerprint == rest_fingerprint(body), "rebuild: garment build"
    check_template(template, rest)


def test_skirt_bridges_the_legs(rest) -> None:
    """Between the knees, at mid-thigh height, the dress is cloth, not two leg tubes."""
    template = load_template("dress", "low")
    _, _, joints, _ = rest
    v = template.vertices
    y = 0.5 * (joints[1, 1] + joints[4, 1])  # halfway from the hips to the knees
    band = v[np.abs(v[:, 1] - y) < 0.03]
    front = band[(np.abs(band[:, 0]) < 0.03) & (band[:, 2] > 0)]
    back = band[(np.abs(band[:, 0]) < 0.03) & (band[:, 2] < 0)]
    assert len(front) and len(back)


def test_build_for_a_body_file_is_cached(tmp_path, monkeypatch, rest) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    built = load_template("tshirt", "low", default_body_path())
    check_template(built, rest)
    cached = list(tmp_path.rglob("tshirt_low.npz"))
    assert len(cached) == 1
    again = load_template("tshirt", "low", default_body_path())
    np.testing.assert_array_equal(again.faces, built.faces)


def test_bad_names() -> None:
    with pytest.raises(ValueError, match="unknown garment"):
        load_template("cape")
    with pytest.raises(ValueError, match="level of detail"):
        load_template("tshirt", "ultra")


def test_cli_info_json() -> None:
    result = CliRunner().invoke(main, ["garment", "info", "dress", "--lod", "low", "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["boundary_loops"] == 4 and summary["clearance_min_m"] > 0.005


def test_cli_bad_body_file(tmp_path) -> None:
    bad = tmp_path / "body.npz"
    bad.write_bytes(b"not a zip")
    result = CliRunner().invoke(main, ["garment", "info", "tshirt", "--body-model", str(bad)])
    assert result.exit_code != 0
    assert "Traceback" not in result.output and result.output.startswith("Error")


def test_surface_nets_sphere() -> None:
    """Reference: a sphere's exact SDF gives a closed, outward, genus-0 mesh on the sphere."""
    h, r = 0.05, 0.7
    ax = np.arange(-1.0, 1.0 + 1e-9, h)
    x, y, z = np.meshgrid(ax, ax, ax, indexing="ij")
    v, f = surface_nets(np.sqrt(x**2 + y**2 + z**2) - r, np.array([-1.0, -1.0, -1.0]), h)
    _, counts = edge_face_counts(f)
    assert (counts == 2).all() and is_manifold(f)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_winding_consistent and mesh.euler_number == 2
    assert mesh.volume > 0  # outward normals
    assert np.abs(np.linalg.norm(v, axis=1) - r).max() < 0.1 * h
    assert abs(mesh.volume / (4 / 3 * np.pi * r**3) - 1) < 0.02


def test_points_inside_matches_trimesh(rest) -> None:
    body_v, body_f, _, _ = rest
    rng = np.random.default_rng(0)
    points = rng.uniform(body_v.min(0), body_v.max(0), size=(1500, 3))
    mesh = trimesh.Trimesh(body_v, body_f, process=False)
    inside = points_inside(body_v, body_f, points)
    assert inside.sum() > 50
    np.testing.assert_array_equal(inside, mesh.contains(points))


def test_inside_mesh_sphere() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    grid = Grid.covering(np.full(3, -0.6), np.full(3, 0.6), 0.04)
    inside = inside_mesh(sphere.vertices, sphere.faces, grid)
    idx = np.argwhere(np.ones(grid.shape, dtype=bool))
    radius = np.linalg.norm(grid.points(idx), axis=1).reshape(grid.shape)
    clear = np.abs(radius - 0.5) > 0.01
    np.testing.assert_array_equal(inside[clear], radius[clear] < 0.5)


def test_lod_transfer_carries_the_rest_shape_within_a_millimetre_or_so() -> None:
    from usd_garment.garment.lod import carry_to_lod, lod_with_vertices, transfer_weights

    high, low = load_template("tshirt", "high"), load_template("tshirt", "low")
    weights = transfer_weights(high, low)
    np.testing.assert_allclose(np.asarray(weights.sum(axis=1)).ravel(), 1.0, atol=1e-6)
    assert (weights.getnnz(axis=1) <= 3).all()
    carried = carry_to_lod(np.stack([high.vertices, high.vertices + 1.0]), "tshirt", "high", "low")
    gap = np.linalg.norm(carried - np.stack([low.vertices, low.vertices + 1.0]), axis=-1)
    assert carried.shape == (2, len(low.vertices), 3) and gap.max() < 1.5e-3
    assert lod_with_vertices("tshirt", len(low.vertices)) == "low"
    assert lod_with_vertices("tshirt", 7) is None
