"""The inside test of the body query against slow, obviously correct references on posed frames
with the arms pressed into the trunk: the exact winding number summed triangle by triangle, and
ray parity (trimesh's ``contains``) wherever the body does not overlap itself."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from usd_garment.body.model import BodyModel
from usd_garment.eval.body_distance import BodyPool, BodySurface, signed_distance


def exact_winding_number(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Σ solid angle / 4π over all triangles (Van Oosterom & Strackee), ``(M,)``."""
    out = np.empty(len(points))
    for s in range(0, len(points), 64):
        rel = vertices[faces][None] - points[s : s + 64, None, None]  # (m, F, 3, 3)
        a, b, c = rel[..., 0, :], rel[..., 1, :], rel[..., 2, :]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = np.einsum("mfi,mfi->mf", a, np.cross(b, c))
        dots = (a * b).sum(-1) * lc + (b * c).sum(-1) * la + (c * a).sum(-1) * lb
        out[s : s + 64] = 2.0 * np.arctan2(det, la * lb * lc + dots).sum(-1) / (4.0 * np.pi)
    return out


@pytest.fixture(scope="module")
def arms_down(body_model: BodyModel) -> tuple[np.ndarray, np.ndarray]:
    """Two frames with the upper arms lowered past the trunk's side (self-intersecting), and
    900 points per frame: near the surface, and in the armpits."""
    pose = np.zeros((2, 24, 3), dtype=np.float32)
    pose[:, 16, 2], pose[:, 17, 2] = -1.45, 1.45  # shoulders: arms down, into the trunk
    pose[1, 16, 0], pose[1, 17, 0] = 0.3, -0.2  # and swung a little
    with torch.no_grad():
        verts = body_model(torch.zeros(10), torch.from_numpy(pose), torch.zeros(2, 3)).vertices
    verts = verts.double().numpy()
    rng = np.random.default_rng(3)
    idx = rng.integers(0, verts.shape[1], size=(2, 600))
    near = np.take_along_axis(verts, idx[..., None], axis=1) + rng.normal(0, 0.01, (2, 600, 3))
    joints = body_model(torch.zeros(10), torch.from_numpy(pose), torch.zeros(2, 3)).joints
    armpit = joints[:, [16, 17]].double().numpy()  # (2, 2, 3) shoulder joints
    pits = armpit[:, :, None] + np.array([0.0, -0.12, 0.0]) + rng.normal(0, 0.04, (2, 2, 150, 3))
    return verts, np.concatenate([near, pits.reshape(2, 300, 3)], axis=1)


def test_inside_matches_the_exact_winding_number(
    body_model: BodyModel, arms_down: tuple[np.ndarray, np.ndarray]
) -> None:
    verts, points = arms_down
    faces = body_model.faces.numpy()
    query = signed_distance(points, verts, BodySurface(faces, verts.shape[1]))
    overlap = 0
    for t in range(2):
        w = exact_winding_number(points[t], verts[t], faces)
        clear = np.abs(w - np.round(w)) < 0.25  # not within a hair of the surface
        np.testing.assert_array_equal(query.inside[t][clear], (w > 0.5)[clear])
        overlap += int((w > 1.5).sum())
        # Ray parity agrees where the body does not overlap itself, and is wrong where it does.
        mesh = trimesh.Trimesh(verts[t], faces, process=False)
        single = clear & (w < 1.5)
        np.testing.assert_array_equal(query.inside[t][single], mesh.contains(points[t][single]))
        # Every point in the overlap of arm and trunk is forced; the rest inside is not.
        assert query.forced[t][w > 1.5].all()
    assert overlap > 8  # the arms really are pressed into the trunk


def test_forced_and_elsewhere_split(
    body_model: BodyModel, arms_down: tuple[np.ndarray, np.ndarray]
) -> None:
    verts, _ = arms_down
    faces = body_model.faces.numpy()
    mesh = trimesh.Trimesh(verts[0], faces, process=False)
    # Inside the chest, 2 cm under its front surface, far from the arms: elsewhere.
    chest = body_model.v_template.numpy()[:, 1].astype(float)
    front = np.argmax(np.where(np.abs(chest - 0.25) < 0.02, verts[0, :, 2], -np.inf))
    point = verts[0, front] - 0.02 * mesh.vertex_normals[front]
    query = signed_distance(point[None, None], verts[:1], BodySurface(faces, verts.shape[1]))
    assert query.inside[0, 0] and query.elsewhere[0, 0] and not query.forced[0, 0]
    assert query.distance[0, 0] == pytest.approx(-0.02, abs=3e-3)


def test_push_out_is_the_same_frame_by_frame(
    body_model: BodyModel, arms_down: tuple[np.ndarray, np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The push-out shares one winding-number hierarchy per body frame across its queries, a
    group of frames at a time; the groups (and a first query made by the caller) change
    nothing."""
    from usd_garment.eval import push_out as module

    verts, points = arms_down
    surface = BodySurface(body_model.faces.numpy(), verts.shape[1])
    whole = module.push_out(points, verts, surface)
    first = signed_distance(points, verts, surface, probe_below=module.PUSH_OUT_EPS)
    monkeypatch.setattr(module, "BLOCK_FRAMES", 1)
    np.testing.assert_array_equal(module.push_out(points, verts, surface, first=first), whole)
    assert (np.abs(whole - points).max(-1) > 0).sum() > 100  # it did move points
    assert not signed_distance(whole, verts, surface, probe_below=1e-3).elsewhere.any()


def test_push_out_in_worker_processes_is_the_same(
    body_model: BodyModel, arms_down: tuple[np.ndarray, np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``dress --workers``: blocks of frames pushed out by spawned processes give the result of
    this process to the bit."""
    from usd_garment.eval import push_out as module

    verts, points = arms_down
    surface = BodySurface(body_model.faces.numpy(), verts.shape[1])
    alone = module.push_out(points, verts, surface)
    monkeypatch.setattr(module, "BLOCK_FRAMES", 1)  # two blocks for two workers
    with BodyPool(2) as pool:
        np.testing.assert_array_equal(module.push_out(points, verts, surface, pool=pool), alone)


def test_signed_distance_in_worker_processes_is_the_same(
    body_model: BodyModel, arms_down: tuple[np.ndarray, np.ndarray], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``eval --workers``: blocks of frames queried by spawned processes give the result of this
    process to the bit."""
    from usd_garment.eval import body_distance as module

    verts, points = arms_down
    surface = BodySurface(body_model.faces.numpy(), verts.shape[1])
    alone = signed_distance(points, verts, surface, probe_below=1e-3)
    monkeypatch.setattr(module, "POOL_FRAMES", 1)  # two blocks for two workers
    with BodyPool(2) as pool:
        pooled = signed_distance(points, verts, surface, probe_below=1e-3, pool=pool)
    for name in ("distance", "closest", "normal", "closest_inside"):
        np.testing.assert_array_equal(getattr(pooled, name), getattr(alone, name))


def test_body_pools_of_one_size_open_together_are_one() -> None:
    """A ``body_pool`` context entered while another of its size is open shares that pool,
    which keeps working until the last of them exits and stops then; one process is no pool."""
    from usd_garment.eval.body_distance import body_pool

    with body_pool(2) as outer:
        with body_pool(2) as inner, body_pool(3) as other, body_pool(1) as alone:
            assert inner is outer and other is not outer and alone is None
        assert outer is not None and list(outer.map(abs, [-3])) == [3]
    with pytest.raises(RuntimeError):  # stopped: it takes no more jobs
        list(outer.map(abs, [-3]))
    with body_pool(2) as later:
        assert later is not outer


def test_dress_pushes_every_lod_variant_in_one_pool(
    body_model: BodyModel, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``dress --lod-variants --workers 2`` with a push-out method: each level is dressed by the
    method in turn, all in one pool of worker processes (not one pool a level)."""
    from usd_garment.dress import dress
    from usd_garment.eval import body_distance
    from usd_garment.methods import get_method
    from usd_garment.motion.procedural import make_motion
    from usd_garment.usd.body_layer import write_body_layer

    made: list[BodyPool] = []

    class CountedPool(BodyPool):
        def __init__(self, workers: int) -> None:
            super().__init__(workers)
            made.append(self)

    monkeypatch.setattr(body_distance, "BodyPool", CountedPool)
    body = tmp_path / "walk.usda"
    write_body_layer(body, make_motion("walk", 2, 30.0, seed=1, body=body_model), body_model)
    method = get_method("lbs+postprocess")
    method.push_out_workers = 2
    dress(body, tmp_path / "v.usdc", method=method, lod_variants=True)
    assert len(made) == 1
