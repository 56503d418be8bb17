"""Collision query and metrics: the signed distance against trimesh, the push-out baseline leaving
no vertex inside the body where plain skinning has some, and ``eval`` agreeing with both."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from tests.dress_helpers import random_motion, strong_motion, torso_template
from usd_garment.body.model import BodyModel
from usd_garment.dress import dress
from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.eval.evaluate import evaluate_layer, posed_body_vertices
from usd_garment.eval.metrics import evaluate_garment, face_joints
from usd_garment.eval.push_out import PUSH_OUT_EPS
from usd_garment.methods import available_methods, get_method
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.read import read_smpl_motion


@pytest.fixture(scope="module")
def closed_body(body_model: BodyModel) -> BodyModel:
    mesh = trimesh.Trimesh(body_model.v_template.numpy(), body_model.faces.numpy(), process=False)
    if not mesh.is_watertight:
        pytest.skip("collision tests need the closed default body")
    return body_model


def test_signed_distance_matches_trimesh(closed_body: BodyModel) -> None:
    motion = random_motion(frames=2, seed=1)
    motion.pose *= 0.3  # mild, so the posed body does not intersect itself
    verts = posed_body_vertices(closed_body, motion)
    faces = closed_body.faces.numpy()
    rng = np.random.default_rng(0)
    idx = rng.integers(0, verts.shape[1], size=(2, 400))
    points = np.take_along_axis(verts, idx[..., None], axis=1) + rng.normal(0, 0.01, (2, 400, 3))
    result = signed_distance(points, verts, BodySurface(faces, verts.shape[1]))
    for t in range(2):
        mesh = trimesh.Trimesh(verts[t], faces, process=False)
        reference = -trimesh.proximity.signed_distance(mesh, points[t])  # trimesh: inside > 0
        np.testing.assert_allclose(result.distance[t], reference, atol=2e-5)
        on_surface = np.abs(mesh.nearest.on_surface(result.closest[t])[1])
        assert on_surface.max() < 1e-5


def test_push_out_removes_the_penetrations_of_skinning(closed_body: BodyModel) -> None:
    template = torso_template(closed_body)
    motion = strong_motion()
    verts = posed_body_vertices(closed_body, motion)
    faces = closed_body.faces.numpy()
    plain = get_method("lbs").predict(motion, closed_body, template)
    pushed = get_method("lbs+postprocess").predict(motion, closed_body, template)
    before = evaluate_garment(plain, verts, faces, motion.fps)
    after = evaluate_garment(pushed, verts, faces, motion.fps)
    assert before.inside_elsewhere_share.max() > 0.001
    assert before.max_elsewhere_mm.max() > 0.5
    assert after.inside_elsewhere_share.max() == 0.0
    assert after.max_elsewhere_mm.max() == 0.0
    moved = np.linalg.norm(pushed - plain, axis=-1) > 0
    query = signed_distance(plain, verts, BodySurface(faces, verts.shape[1]))
    assert not moved[query.distance > PUSH_OUT_EPS].any()  # only vertices nearer than ε move
    assert moved[query.elsewhere].all()
    assert not moved[query.forced].any()  # nowhere to go: a limb is pressed into the body


def test_eval_of_written_layers_agrees_with_the_metrics(
    closed_body: BodyModel, tmp_path: Path
) -> None:
    template = torso_template(closed_body)
    motion = strong_motion(frames=8)
    source = tmp_path / "body.usda"
    write_body_layer(source, motion, closed_body)
    layers = {}
    for method in ("lbs", "lbs+postprocess"):
        layers[method] = tmp_path / f"{method}.usdc"
        dress(source, layers[method], method=method, template=template)
    plain, _ = evaluate_layer(layers["lbs"], source, reference=layers["lbs+postprocess"])
    pushed, codes = evaluate_layer(layers["lbs+postprocess"], source)
    np.testing.assert_array_equal(codes, motion.time_codes)

    verts = posed_body_vertices(closed_body, motion)
    direct = {m: get_method(m).predict(motion, closed_body, template) for m in layers}
    expected = evaluate_garment(direct["lbs"], verts, closed_body.faces.numpy(), motion.fps)
    np.testing.assert_allclose(
        plain.inside_share, expected.inside_share, atol=2 / len(template.vertices)
    )
    assert plain.summary()["inside_share"] > 0.0
    assert pushed.summary()["inside_elsewhere_share"] == 0.0
    shift_mm = 1e3 * np.linalg.norm(direct["lbs"] - direct["lbs+postprocess"], axis=-1).mean(1)
    np.testing.assert_allclose(plain.reference_mm, shift_mm, atol=1e-3)
    assert np.isnan(pushed.reference_mm).all()


def test_metrics_jitter_and_nans() -> None:
    body = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    t, fps = 6, 30.0
    verts = np.repeat(body.vertices[None], t, axis=0)
    times = np.arange(t) / fps
    points = np.repeat(body.vertices[None] * 2.0, t, axis=0)
    points[..., 0] += 0.5 * 3.0 * times[:, None] ** 2  # constant acceleration 3 m/s² along x
    points[2, 5] = np.nan
    points[:, 7] = 0.0  # the sphere's centre: inside, 100 mm deep
    m = evaluate_garment(points, verts, body.faces, fps)
    np.testing.assert_array_equal(m.nan_count, [0, 0, 1, 0, 0, 0])
    n = len(body.vertices)
    # Vertex 7 stands still; vertex 5 is left out of the frames next to its NaN (1 to 3).
    moving = [(n - 2) / (n - 1)] * 3 + [(n - 1) / n]
    np.testing.assert_allclose(m.acceleration[1:-1], 3.0 * np.array(moving), rtol=1e-6)
    assert np.isnan(m.acceleration[[0, -1]]).all()
    np.testing.assert_allclose(m.inside_share, [1 / n, 1 / n, 1 / (n - 1), 1 / n, 1 / n, 1 / n])
    np.testing.assert_allclose(m.max_penetration_mm, 100.0, rtol=0.05)
    assert m.summary()["nan_count"] == 1
    assert m.to_json()["per_frame"]["acceleration"][0] is None


def test_the_error_to_a_reference_splits_into_the_whole_garments_offset_and_the_rest() -> None:
    """A garment that is its reference moved up by 30 mm in frame 0, and in frame 1 the same
    plus 4 mm outward from the centre on every vertex: the offset is 30 mm in both frames, the
    error without it 0 then 4 mm (outward moves average out of the offset); a NaN vertex is
    left out."""
    body = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    verts = np.repeat(body.vertices[None], 2, axis=0)
    reference = verts * 1.5  # outside the body
    points = reference + np.array([0.0, 0.03, 0.0])
    out = reference[1] / np.linalg.norm(reference[1], axis=-1, keepdims=True)
    points[1] += 0.004 * out
    points[1, 3] = np.nan
    m = evaluate_garment(points, verts, body.faces, 30.0, reference=reference)
    np.testing.assert_allclose(m.reference_shift_mm, [30.0, 30.0], atol=0.05)
    np.testing.assert_allclose(m.reference_unshifted_mm, [0.0, 4.0], atol=0.05)
    assert m.reference_mm[0] == pytest.approx(30.0)
    assert m.reference_mm[1] > 30.0
    plain = evaluate_garment(points, verts, body.faces, 30.0)
    assert np.isnan(plain.reference_shift_mm).all() and np.isnan(plain.reference_unshifted_mm).all()


def test_eval_counts_where_the_vertices_inside_elsewhere_are() -> None:
    """Two separate spheres as the body's parts 'spine2' (6) and 'left_shoulder' (16): points
    inside each are counted on that part, by the triangle their closest point lies on."""
    a = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    b = a.copy()
    b.apply_translation([0.5, 0.0, 0.0])
    verts = np.concatenate([a.vertices, b.vertices])[None].repeat(2, axis=0)
    faces = np.concatenate([a.faces, b.faces + len(a.vertices)])
    parts = np.repeat([6, 16], len(a.faces))
    points = np.array([[0.0, 0.0, 0.05], [0.02, 0.0, 0.0], [0.0, -0.03, 0.0],  # in sphere a
                       [0.5, 0.0, 0.06], [0.2, 0.0, 0.0]])[None].repeat(2, axis=0)  # fmt: skip
    m = evaluate_garment(points, verts, faces, 30.0, face_parts=parts)
    np.testing.assert_allclose(m.inside_elsewhere_share, [0.8, 0.8])
    assert m.elsewhere_part_counts is not None
    assert (
        m.elsewhere_part_counts[[6, 16]].tolist() == [6, 2] and m.elsewhere_part_counts.sum() == 8
    )
    assert m.elsewhere_by_part() == {"spine2": 0.75, "left_shoulder": 0.25}
    assert m.to_json()["elsewhere_by_part"] == {"spine2": 0.75, "left_shoulder": 0.25}
    assert evaluate_garment(points, verts, faces, 30.0).elsewhere_by_part() == {}
    assert face_joints(np.eye(3)[[0, 0, 2, 2]], np.array([[0, 1, 2], [1, 2, 3]])).tolist() == [0, 2]


def test_methods_registry() -> None:
    assert {"lbs", "lbs+postprocess"} <= set(available_methods())
    with pytest.raises(ValueError, match="unknown method"):
        get_method("nope")


def test_lbs_follows_the_body_under_shape_and_translation(closed_body: BodyModel) -> None:
    template = torso_template(closed_body, offset=0.0)
    motion = random_motion(frames=3, seed=2)
    points = get_method("lbs").predict(motion, closed_body, template)
    verts = posed_body_vertices(closed_body, motion)
    # A zero-offset garment cut from the body follows its vertices exactly (same weights/shape).
    index = torch.cdist(torch.from_numpy(template.vertices), closed_body.v_template).argmin(1)
    np.testing.assert_allclose(points, verts[:, index.numpy()], atol=1e-5)


def test_acceleration_across_a_cut_of_the_motion(closed_body: BodyModel, tmp_path: Path) -> None:
    """A body teleported 0.5 m at frame 4 (a cut, ``root_cuts``): ``evaluate_garment`` given
    the cut does not measure the garment's acceleration on the two frames whose central
    difference spans the jump (450 m/s² there at 30 fps, the body's jump), and measures the
    other frames as before. ``eval`` of a layer measures those two frames with the jump taken
    out (a jump of the root alone, one motion going on): as the body without the jump. A cut
    the body layer declares (a restart) is not measured across."""
    from usd_garment.motion.cuts import root_cuts

    template = torso_template(closed_body)
    motion = strong_motion(frames=8)
    motion.trans[4:, 0] += 0.5
    assert root_cuts(motion) == (4,)
    source = tmp_path / "body.usda"
    write_body_layer(source, motion, closed_body)
    layer = tmp_path / "lbs.usdc"
    dress(source, layer, method="lbs", template=template)
    measured, _ = evaluate_layer(layer, source)
    verts = posed_body_vertices(closed_body, motion)
    points = get_method("lbs").predict(motion, closed_body, template)
    faces = closed_body.faces.numpy()
    across = evaluate_garment(points, verts, faces, motion.fps).acceleration
    assert across[3:5].min() > 400.0  # the jump: 0.5 m · 30² / s²
    cut = evaluate_garment(points, verts, faces, motion.fps, cuts=(4,)).acceleration
    assert np.isnan(cut[[0, 3, 4, 7]]).all()
    np.testing.assert_array_equal(cut[[1, 2, 5, 6]], across[[1, 2, 5, 6]])
    np.testing.assert_allclose(measured.acceleration[[1, 2, 5, 6]], cut[[1, 2, 5, 6]], rtol=1e-5)
    free = get_method("lbs").predict(strong_motion(frames=8), closed_body, template)
    steady = evaluate_garment(free, verts, faces, motion.fps).acceleration
    np.testing.assert_allclose(measured.acceleration[3:5], steady[3:5], rtol=1e-5)
    # The same cut declared in the body layer (``smpl:cuts``), the root not moved: the layer's
    # acceleration is not measured across it either.
    declared = tmp_path / "declared.usda"
    write_body_layer(declared, replace(strong_motion(frames=8), cut_times=(4.0,)), closed_body)
    assert read_smpl_motion(declared, closed_body)[0].cut_times == (4.0,)
    dress(declared, tmp_path / "still.usdc", method="lbs", template=template)
    still, _ = evaluate_layer(tmp_path / "still.usdc", declared)
    assert np.isnan(still.acceleration[[0, 3, 4, 7]]).all()
    assert np.isfinite(still.acceleration[[1, 2, 5, 6]]).all()
