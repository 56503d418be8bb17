"""Projection to canonical space: recovers a garment posed by M_G itself, keeps it out of the
canonical body, and the unposing baselines invert their own skinning."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from tests.models import untrained_model
from usd_garment.body.io import load_body_model
from usd_garment.canonical.dataset import CanonicalSet, load_canonical_set, save_canonical_set
from usd_garment.canonical.floor import network_floor, pose_canonical, representation_floor
from usd_garment.canonical.projection import ProjectionSettings, project_sequence
from usd_garment.canonical.strain import TriangleStrain
from usd_garment.canonical.unpose import (
    skin_body_vertices,
    unpose_constant_weights,
    unpose_nearest_vertex,
)
from usd_garment.cli.main import main
from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.fields.body_fields import load_body_fields
from usd_garment.garment.library import load_template
from usd_garment.garment.model import GarmentModel
from usd_garment.methods.learned import predict_latents
from usd_garment.methods.learned_model import (
    save_learned_model,
)
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.errors import UsdInputError
from usd_garment.usd.garment_layer import GarmentFrames, write_garment_layer
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion

FRAMES = 3


@pytest.fixture(scope="module")
def body():
    return load_body_model()


@pytest.fixture(scope="module")
def template():
    return load_template("tshirt", "low")


@pytest.fixture(scope="module")
def motion():
    """Betas ``(10,)``, pose ``(T, 24, 3)`` and trans ``(T, 3)``: arms lowering, a twist."""
    pose = np.zeros((FRAMES, 24, 3), dtype=np.float32)
    pose[:, 16, 2] = -np.linspace(0.0, 0.8, FRAMES)  # left shoulder down
    pose[:, 17, 2] = np.linspace(0.0, 0.8, FRAMES)
    pose[:, 3, 1] = np.linspace(0.0, 0.3, FRAMES)
    trans = np.linspace([0.0, 0.0, 0.0], [0.05, 0.01, 0.1], FRAMES).astype(np.float32)
    betas = np.array([1.0, -0.5, 0.3, 0, 0, 0, 0, 0, 0, 0], dtype=np.float32)
    return betas, pose, trans


def test_strain_is_zero_at_rest_and_rotation_invariant(template):
    strain = TriangleStrain(torch.as_tensor(template.vertices), torch.as_tensor(template.faces))
    rest = torch.as_tensor(template.vertices)[None]
    assert strain.energy(rest).item() < 1e-8
    angle = torch.tensor(0.7)
    c, s = torch.cos(angle), torch.sin(angle)
    rot = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    assert strain.energy(rest @ rot.T + 1.0).item() < 1e-6
    stretched = rest * torch.tensor([1.1, 1.0, 1.0])
    assert strain.energy(stretched).item() > 1e-2


def test_projection_recovers_a_garment_posed_by_the_model(body, template, motion):
    betas, pose, trans = motion
    model = GarmentModel(body, load_body_fields())
    # A known canonical garment: the template with a smooth bulge, outside the body.
    x_true = template.vertices + np.array([0.0, 0.0, 0.01]) * np.sin(
        8.0 * template.vertices[:, 1:2]
    ).clip(min=0)
    x_true = np.repeat(x_true[None], FRAMES, axis=0).astype(np.float32)
    with torch.no_grad():
        posed = model(
            torch.as_tensor(x_true), torch.as_tensor(betas), torch.as_tensor(pose),
            torch.as_tensor(trans),
        ).vertices.numpy()  # fmt: skip
    done: list[int] = []
    result = project_sequence(
        model, template.vertices, template.faces, posed, betas, pose, trans,
        ProjectionSettings(iterations=20, chunk=2), progress=done.append,
    )  # fmt: skip
    assert done == [2, 3]
    assert result.canonical.shape == x_true.shape
    assert result.error.max() < 2e-4  # m: well under a millimetre
    assert np.abs(result.canonical - x_true).max() < 5e-3
    assert np.linalg.norm(result.canonical - x_true, axis=-1).mean() < 5e-4
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    rest_body = np.repeat(body.v_template.numpy()[None], FRAMES, axis=0)
    inside = signed_distance(result.canonical, rest_body, surface).distance < 0
    assert inside.mean() == 0.0


def test_projection_rejects_mismatched_input(body, template, motion):
    betas, pose, trans = motion
    model = GarmentModel(body, load_body_fields())
    with pytest.raises(ValueError, match="points must be"):
        project_sequence(model, template.vertices, template.faces, np.zeros((FRAMES, 5, 3)),
                         betas, pose, trans)  # fmt: skip
    nan = np.full((FRAMES, len(template.vertices), 3), np.nan)
    with pytest.raises(ValueError, match="NaN"):
        project_sequence(model, template.vertices, template.faces, nan, betas, pose, trans)


@pytest.mark.parametrize("baseline", ["constant", "nearest"])
def test_baselines_invert_their_own_skinning(body, template, motion, baseline):
    betas, pose, trans = motion
    # Posed input: the template skinned with constant nearest-vertex weights.
    index = np.broadcast_to(
        unpose_constant_weights(body, template, template.vertices[None], betas, pose[:1],
                                trans[:1]).body_vertex[0], (FRAMES, len(template.vertices)),
    )  # fmt: skip
    canonical = np.repeat(template.vertices[None], FRAMES, axis=0)
    posed = skin_body_vertices(body, canonical, index, betas, pose, trans)
    if baseline == "constant":
        result = unpose_constant_weights(body, template, posed, betas, pose, trans)
        np.testing.assert_allclose(result.canonical, canonical, atol=1e-5)
    else:
        result = unpose_nearest_vertex(body, posed, betas, pose, trans)
    assert result.canonical.shape == posed.shape and np.isfinite(result.canonical).all()
    again = skin_body_vertices(body, result.canonical, result.body_vertex, betas, pose, trans)
    np.testing.assert_allclose(again, posed, atol=1e-5)


def _write_inputs(tmp_path, body, template, motion, points, settings="", name="sim.usdc"):
    """A body layer and a garment layer ``name`` holding ``points`` ``(T, N, 3)`` and the
    solver ``settings``."""
    betas, pose, trans = motion
    body_path, sim_path = tmp_path / "body.usda", tmp_path / name
    write_body_layer(body_path, SmplMotion(betas, pose, trans, fps=30.0), body, with_mesh=False)
    read_motion, info = read_smpl_motion(body_path, body)
    garment = GarmentFrames("tshirt", "tshirt", template.faces, template.uvs, points, "sim",
                            "tshirt", "1", body.name, settings)  # fmt: skip
    write_garment_layer(sim_path, info, [garment], read_motion.time_codes)
    return body_path, sim_path


def test_project_command_writes_the_canonical_set(tmp_path, body, template, motion):
    betas, pose, _ = motion
    model = GarmentModel(body, load_body_fields())
    x = np.repeat(template.vertices[None], FRAMES, axis=0)
    with torch.no_grad():
        posed = model(torch.as_tensor(x), *(torch.as_tensor(a) for a in motion)).vertices.numpy()
    body_path, sim_path = _write_inputs(tmp_path, body, template, motion, posed)
    out = tmp_path / "canonical.npz"
    args = ["project", str(sim_path), str(sim_path), "--body", str(body_path), "-o", str(out),
            "--lod", "low", "--iterations", "5", "--strain-weight", "2e-6"]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    data = load_canonical_set(out)
    assert data.canonical.shape == (2 * FRAMES, len(template.vertices), 3)
    assert data.num_sequences == 2 and data.sources == [str(sim_path)] * 2
    np.testing.assert_allclose(data.pose[data.sequence(1)], pose, atol=1e-5)
    np.testing.assert_allclose(data.betas[0], betas, atol=1e-6)
    assert data.error.max() < 2e-4
    assert data.metadata["garment"] == "tshirt" and data.metadata["lod"] == "low"
    assert data.metadata["projection"]["strain_weight"] == 2e-6


def _write_dataset(folder, body, template, motion, posed):
    """A 'dataset make'-like folder: two ok sequences (train, test) and a bad one."""
    folder.mkdir()
    body_path, sim_path = _write_inputs(folder, body, template, motion, posed)
    files = {"body": body_path.name, "garment": sim_path.name}
    sequences = [
        {"name": "m00_s0", "split": "test", "status": "ok", "files": files},
        {"name": "m01_s0", "split": "train", "status": "ok", "files": files},
        {"name": "m02_s0", "split": "train", "status": "bad", "files": {}},
    ]
    manifest = {"format": 1, "garment": "tshirt", "lod": "low", "sequences": sequences}
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return sim_path


def test_project_manifest_with_workers_matches_one_process(tmp_path, body, template, motion):
    model = GarmentModel(body, load_body_fields())
    x = np.repeat(template.vertices[None], FRAMES, axis=0) * np.float32(1.01)
    with torch.no_grad():
        posed = model(torch.as_tensor(x), *(torch.as_tensor(a) for a in motion)).vertices.numpy()
    sim_path = _write_dataset(tmp_path / "set", body, template, motion, posed)
    outputs = {}
    for workers in (1, 2):
        out = tmp_path / f"canonical_{workers}.npz"
        args = ["project", "--manifest", str(tmp_path / "set" / "manifest.json"), "-o", str(out),
                "--iterations", "5", "--workers", str(workers)]  # fmt: skip
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, result.output
        outputs[workers] = load_canonical_set(out)
    one, two = outputs[1], outputs[2]
    # Splits in the default order (train, validation, test), the bad sequence left out.
    assert one.splits == two.splits == ["train", "test"]
    assert one.split_sequences("test") == [1]
    assert one.sources == [str(sim_path)] * 2 and one.metadata["lod"] == "low"
    # Same solve; only float rounding differs (one torch thread in the workers).
    np.testing.assert_allclose(one.canonical, two.canonical, atol=1e-5)
    assert one.error.max() < 2e-4
    only_test = tmp_path / "test_only.npz"
    args = ["project", "--manifest", str(tmp_path / "set"), "--split", "test", "-o",
            str(only_test), "--iterations", "0"]  # fmt: skip
    assert CliRunner().invoke(main, args).exit_code == 0
    assert load_canonical_set(only_test).splits == ["test"]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--split", "holdout"], "unknown split 'holdout'"),
        (["--split", "validation"], "no ok sequence in the splits validation"),
        (["sim.usdc"], "give either SIM_LAYER... with --body, or --manifest"),
    ],
)
def test_project_manifest_bad_input(tmp_path, body, template, motion, extra, message):
    rest = np.repeat(template.vertices[None], FRAMES, axis=0)
    _write_dataset(tmp_path / "set", body, template, motion, rest)
    out = tmp_path / "canonical.npz"
    args = ["project", "--manifest", str(tmp_path / "set"), "-o", str(out), *extra]
    result = CliRunner().invoke(main, args)
    assert result.exit_code != 0 and message in result.output, result.output
    assert "Traceback" not in result.output and not out.exists()


def test_project_command_rejects_another_garment_mesh(tmp_path, body, template, motion):
    rest = np.repeat(template.vertices[None], FRAMES, axis=0)
    body_path, sim_path = _write_inputs(tmp_path, body, template, motion, rest)
    out = tmp_path / "canonical.npz"
    args = ["project", str(sim_path), "--body", str(body_path), "-o", str(out), "--lod", "high"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1
    assert "is not the tshirt 'high' template" in result.output
    assert "Traceback" not in result.output and not out.exists()


def test_project_update_appends_only_new_layers(tmp_path, body, template, motion):
    rest = np.repeat(template.vertices[None], FRAMES, axis=0) * np.float32(1.01)
    body_path, first = _write_inputs(tmp_path, body, template, motion, rest)
    second = tmp_path / "second.usdc"
    second.write_bytes(first.read_bytes())
    out = tmp_path / "canonical.npz"
    common = ["--body", str(body_path), "-o", str(out), "--lod", "low", "--iterations", "3"]
    result = CliRunner().invoke(main, ["project", str(first), *common])
    assert result.exit_code == 0, result.output
    assert f"1 sequence(s), {FRAMES} frames projected in" in result.output
    before = load_canonical_set(out)
    result = CliRunner().invoke(main, ["project", str(first), str(second), "--update", *common])
    assert result.exit_code == 0, result.output
    # The line says what this run did, then what the set holds; the set's times add up.
    assert f"1 sequence(s), {FRAMES} frames projected in" in result.output
    assert f"the set: 2 sequences, {2 * FRAMES} frames" in result.output
    assert f"wrote {out}" in result.output
    after = load_canonical_set(out)
    run = after.metadata["last_run"]
    assert (run["sequences"], run["frames"], run["workers"]) == (1, FRAMES, 1)  # one sequence
    assert after.metadata["seconds"] == before.metadata["seconds"] + run["seconds"]
    assert after.sources == [str(first), str(second)] and after.splits == ["train", "train"]
    np.testing.assert_array_equal(after.canonical[after.sequence(0)], before.canonical)
    np.testing.assert_allclose(after.canonical[after.sequence(1)], before.canonical, atol=1e-5)
    assert list(after.frame_offsets) == [0, FRAMES, 2 * FRAMES]
    # Nothing new: the file is left as it is; other settings: refused, file untouched.
    written = out.read_bytes()
    result = CliRunner().invoke(main, ["project", str(second), "--update", *common])
    assert result.exit_code == 0 and out.read_bytes() == written, result.output
    assert "no layer new to it; the set: 2 sequences" in result.output
    assert f"{out} left as it was" in result.output and "wrote" not in result.output
    other = [*common[:-1], "4"]
    result = CliRunner().invoke(main, ["project", str(first), "--update", *other])
    assert result.exit_code != 0 and "projection settings" in result.output, result.output
    assert "Traceback" not in result.output and out.read_bytes() == written


def test_project_records_the_frames_the_simulation_flagged(tmp_path, body, template, motion):
    """The canonical set keeps each frame's flag from its layer's per-frame quality (none for a
    layer that records none); ``--update`` gives a set projected before flags were kept its
    flags from its layers, and leaves it without when a layer is gone."""
    rest = np.repeat(template.vertices[None], FRAMES, axis=0) * np.float32(1.01)
    flagged = json.dumps({"per_frame": {"bad": [0, 1, 0]}})
    body_path, first = _write_inputs(tmp_path, body, template, motion, rest, flagged)
    _, second = _write_inputs(tmp_path, body, template, motion, rest, "{}", "second.usdc")
    out = tmp_path / "canonical.npz"
    common = ["--body", str(body_path), "-o", str(out), "--lod", "low", "--iterations", "0"]
    result = CliRunner().invoke(main, ["project", str(first), str(second), *common])
    assert result.exit_code == 0, result.output
    assert "frames the simulation flagged: 1 in 1 sequence(s)" in result.output
    data = load_canonical_set(out)
    assert data.flags().tolist() == [False, True, False, False, False, False]
    data.flagged = None  # as projected before flags were kept
    save_canonical_set(out, data)
    assert load_canonical_set(out).flagged is None
    result = CliRunner().invoke(main, ["project", str(first), "--update", *common])
    assert result.exit_code == 0, result.output
    assert load_canonical_set(out).flags().tolist() == [False, True, False, False, False, False]
    save_canonical_set(out, data)
    second.unlink()
    result = CliRunner().invoke(main, ["project", str(first), "--update", *common])
    assert result.exit_code == 0 and "flagged: not recorded" in result.output, result.output
    with pytest.raises(ValueError, match="project its layers again"):
        load_canonical_set(out).flags()


def test_a_layer_whose_quality_record_does_not_match_its_samples_is_refused(
    tmp_path, body, template, motion
):
    rest = np.repeat(template.vertices[None], FRAMES, axis=0)
    settings = json.dumps({"per_frame": {"bad": [0, 1]}})
    _, sim = _write_inputs(tmp_path, body, template, motion, rest, settings)
    with pytest.raises(UsdInputError, match="quality of 2 frames for 3 time samples"):
        read_garment_layer(sim)
    _, sim = _write_inputs(tmp_path, body, template, motion, rest, "not json", "other.usdc")
    assert read_garment_layer(sim)[2].flagged.tolist() == [False] * FRAMES


def _floor_set(template, motion, sim_path, canonical_a, canonical_b):
    """Two sequences of one simulated layer, with the canonical targets ``canonical_a`` and
    ``canonical_b`` ``(T, N, 3)``."""
    betas, pose, trans = motion
    zeros = np.zeros(2 * FRAMES, np.float32)
    return CanonicalSet(
        canonical=np.concatenate([canonical_a, canonical_b]).astype(np.float32),
        frame_offsets=np.array([0, FRAMES, 2 * FRAMES]),
        betas=np.stack([betas, betas]),
        pose=np.concatenate([pose, pose]),
        trans=np.concatenate([trans, trans]),
        fps=np.full(2, 30.0),
        error=zeros,
        max_error=zeros,
        template=template.vertices,
        faces=template.faces,
        sources=[str(sim_path)] * 2,
        splits=["train", "test"],
    )


def test_floor_poses_the_targets_back_beside_the_simulation(tmp_path, body, template, motion):
    betas, pose, trans = motion
    fields = load_body_fields()
    x = np.repeat(template.vertices[None], FRAMES, axis=0).astype(np.float32)
    posed = pose_canonical(GarmentModel(body, fields), x, betas, pose, trans)
    _, sim_path = _write_inputs(tmp_path, body, template, motion, posed)
    # Targets of the second sequence: 20 vertices sunk onto the chest joint (inside the trunk).
    _, joints = body.shaped(torch.as_tensor(betas)[None])
    sunk = x.copy()
    chest = np.argsort(np.linalg.norm(template.vertices - joints[0, 9].numpy(), axis=1))[:20]
    sunk[:, chest] = joints[0, 9].numpy()
    data = _floor_set(template, motion, sim_path, x, sunk)
    exact, moved = representation_floor(data, body, fields)
    assert (exact.split, moved.split, exact.frames) == ("train", "test", FRAMES)
    assert exact.reprojection_mm < 0.01  # the simulation is M_G(X) itself
    for key in ("inside_share", "inside_elsewhere_share", "inside_forced_share"):
        assert exact.reposed[key] == pytest.approx(exact.simulation[key], abs=1e-9)
    assert moved.simulation == exact.simulation
    assert moved.reprojection_mm > 1.0
    assert moved.reposed["inside_share"] >= exact.reposed["inside_share"] + 19 / len(x[0])
    assert representation_floor(data, body, fields, splits=["test"]) == [moved]
    data.canonical = data.canonical[:, :-1]
    with pytest.raises(ValueError, match="holds 3 frames"):
        representation_floor(data, body, fields)


def test_dataset_floor_command_prints_a_table_per_split(tmp_path, body, template, motion):
    betas, pose, trans = motion
    x = np.repeat(template.vertices[None], FRAMES, axis=0).astype(np.float32)
    posed = pose_canonical(GarmentModel(body, load_body_fields()), x, betas, pose, trans)
    _, sim_path = _write_inputs(tmp_path, body, template, motion, posed)
    save_canonical_set(tmp_path / "set.npz", _floor_set(template, motion, sim_path, x, x))
    result = CliRunner().invoke(main, ["dataset", "floor", str(tmp_path / "set.npz")])
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    assert lines[0].startswith("sequence | split | frames | reprojection mm")
    assert [line.split(" | ")[:3] for line in lines[-2:]] == [
        ["all", "train", str(FRAMES)],
        ["all", "test", str(FRAMES)],
    ]
    result = CliRunner().invoke(main, ["dataset", "floor", str(tmp_path / "set.npz"), "--json",
                                       "--split", "test"])  # fmt: skip
    assert result.exit_code == 0, result.output
    (row,) = json.loads(result.output)
    assert row["split"] == "test" and row["reprojection_mm"] < 0.01
    bad = CliRunner().invoke(main, ["dataset", "floor", str(tmp_path / "set.npz"), "--split", "x"])
    assert bad.exit_code != 0 and "unknown split" in bad.output
    save_learned_model(tmp_path / "model", untrained_model(body, template))
    args = ["dataset", "floor", str(tmp_path / "set.npz"), "--model", str(tmp_path / "model")]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "sequence | split | frames | decoder best fit mm | networks mm" in result.output
    result = CliRunner().invoke(main, [*args, "--json", "--split", "test"])
    (row,) = json.loads(result.output)
    assert row["reprojection_mm"] < 0.01 and 0.0 < row["decoder_fit_mm"] <= row["networks_mm"]


def test_network_floor_splits_the_error_into_best_fit_and_prediction(body, template, motion):
    """The decoder's best fit recovers garments that are decodings; the networks' figure is
    the distance of the decoded regressor codes; both are per sequence and split."""
    betas, pose, trans = motion
    model = untrained_model(body, template)
    z_true = 0.5 * torch.randn(FRAMES, 25, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        decoded = model.decode(z_true).numpy()
    rest = np.repeat(template.vertices[None], FRAMES, axis=0).astype(np.float32)
    data = _floor_set(template, motion, "unread.usdc", decoded, rest)
    exact, other = network_floor(data, model)
    assert (exact.split, other.split, exact.frames) == ("train", "test", FRAMES)
    assert exact.networks_mm > 1.0 and exact.decoder_fit_mm < 0.25 * exact.networks_mm
    assert other.decoder_fit_mm <= other.networks_mm
    z = predict_latents(model, SmplMotion(betas=betas, pose=pose, trans=trans, fps=30.0))
    with torch.no_grad():
        expected = 1e3 * float((model.decode(z) - torch.as_tensor(decoded)).norm(dim=-1).mean())
    assert exact.networks_mm == pytest.approx(expected, rel=1e-5)
    assert network_floor(data, model, splits=["test"]) == [other]
    data.canonical = data.canonical[:, :-1]
    with pytest.raises(ValueError, match="1015 vertices"):
        network_floor(data, model)


def test_canonical_push_out_moves_only_the_vertices_near_the_body(template):
    from usd_garment.canonical.push_out import LIPSCHITZ, push_out_canonical

    fields = load_body_fields()
    x = torch.as_tensor(template.vertices, dtype=torch.float32)
    with torch.enable_grad():
        p = x.clone().requires_grad_(True)
        (grad,) = torch.autograd.grad(fields.sdf(p).sum(), p)
    d = fields.sdf(x)
    normal = grad / grad.norm(dim=-1, keepdim=True)
    # Frame 1: a third of the vertices 2 mm .. 3 cm out sunk 5 mm into the canonical body.
    sunk = ((d > 2e-3) & (d < 3e-2)).nonzero().squeeze(1)[::3]
    assert sunk.numel() > 10
    moved = x.clone()
    moved[sunk] -= (d[sunk] + 5e-3).unsqueeze(-1) * normal[sunk]
    batch = torch.stack([x, moved])
    assert (fields.sdf(batch[1, sunk]) < 0).float().mean() > 0.9
    out, floor = push_out_canonical(batch, fields.sdf)
    assert out.shape == batch.shape
    assert fields.sdf(out).min() > 2e-3 - 5e-4
    untouched = fields.sdf(batch) >= 2e-3
    assert torch.equal(out[untouched], batch[untouched])
    back = (out[1, sunk] - x[sunk]).norm(dim=-1)  # out along the line it was sunk on, to ε
    assert float((back - (d[sunk] - 2e-3)).abs().mean()) < 1.5e-3
    # The floor bounds the pushed garment's SDF from below (the moved ones to Newton's
    # accuracy), and seeds a later push of points near it: sunk again by 1 mm, the same
    # vertices are looked up and moved as from the mean's bound, with fewer lookups.
    assert floor.shape == batch.shape[:2]
    assert bool((floor <= fields.sdf(out) + 5e-4).all())
    again = out - 1e-3 * torch.nn.functional.normalize(out - out.mean(dim=1, keepdim=True), dim=-1)
    looked: list[int] = []

    def sdf(points: torch.Tensor) -> torch.Tensor:
        looked.append(points.numel() // 3)
        return fields.sdf(points)

    seeded, _ = push_out_canonical(again, sdf, floor=floor - LIPSCHITZ * 1e-3)
    by_floor = sum(looked)
    looked.clear()
    assert torch.equal(seeded, push_out_canonical(again, sdf)[0])
    assert by_floor < sum(looked) - x.shape[0]  # not even the mean's lookups
