"""The garment layer: AMASS → body layer → dress → a layer that composes over the input, validates,
reads back what was written (value clips too), and lands in the same place whatever the rig."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from pxr import Gf, Sdf, Usd, UsdGeom

from tests.dress_helpers import random_motion, torso_template
from tests.rigs import RigStyle, write_rig
from usd_garment.body.measure import heights
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.dress import dress
from usd_garment.methods import get_method
from usd_garment.usd import garment_layer
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.garment_read import read_garment_info, read_garment_layer
from usd_garment.usd.read import read_smpl_motion
from usd_garment.usd.stage import canonical_to_world_matrix
from usd_garment.usd.validate import validate_layer


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def amass_layer(tmp_path: Path, body_model: BodyModel) -> Path:
    """An AMASS-like npz (Z-up, SMPL-H poses, 60 fps) imported as a USD body layer."""
    rng = np.random.default_rng(3)
    t = 12
    poses = np.zeros((t, 156))
    poses[:, :3] = [np.pi / 2, 0.0, 0.0]  # AMASS is Z-up: stand the body up
    poses[:, 3:66] = 0.3 * np.sin(np.linspace(0, 3, t))[:, None] * rng.normal(size=63)
    trans = np.zeros((t, 3))
    trans[:, 1] = np.linspace(0.0, 0.6, t)
    trans[:, 2] = 0.9
    npz = tmp_path / "walk.npz"
    np.savez(npz, poses=poses, trans=trans, betas=0.5 * rng.normal(size=16), gender="neutral",
             mocap_framerate=60.0)  # fmt: skip
    out = tmp_path / "walk.usda"
    result = CliRunner().invoke(main, ["import-amass", str(npz), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out


def _bounds(stage: Usd.Stage, path: str, time: float) -> Gf.Range3d:
    cache = UsdGeom.BBoxCache(Usd.TimeCode(time), [UsdGeom.Tokens.default_])
    return cache.ComputeWorldBound(stage.GetPrimAtPath(path)).ComputeAlignedRange()


def test_round_trip_composes_validates_and_reads_back(
    amass_layer: Path, tmp_path: Path, body_model: BodyModel
) -> None:
    template = torso_template(body_model)
    before = _digest(amass_layer)
    out, root = tmp_path / "tshirt.usdc", tmp_path / "shot.usda"
    result = dress(amass_layer, out, method="lbs", template=template, root_layer=root)
    assert result.outputs == [out, root]
    assert _digest(amass_layer) == before
    assert validate_layer(out) == []
    assert validate_layer(root) == []

    motion, info = read_smpl_motion(amass_layer, body_model)
    expected = get_method("lbs").predict(motion, body_model, template)
    points, faces, ginfo = read_garment_layer(out)
    np.testing.assert_allclose(points, expected, atol=2e-6)
    np.testing.assert_array_equal(faces, template.faces)
    np.testing.assert_array_equal(ginfo.time_codes, motion.time_codes)
    alone = read_garment_info(out)  # the description without the points
    assert (alone.mesh, alone.method) == (ginfo.mesh, ginfo.method)
    for got, read in ((alone.time_codes, ginfo.time_codes), (alone.flagged, ginfo.flagged)):
        np.testing.assert_array_equal(got, read)
    np.testing.assert_array_equal(alone.canonical_to_local, ginfo.canonical_to_local)

    layer = Sdf.Layer.FindOrOpen(str(out))
    source = Usd.Stage.Open(str(amass_layer))
    assert layer.defaultPrim == source.GetDefaultPrim().GetName()
    assert layer.timeCodesPerSecond == source.GetTimeCodesPerSecond()
    assert (layer.startTimeCode, layer.endTimeCode) == (
        source.GetStartTimeCode(),
        source.GetEndTimeCode(),
    )

    stage = Usd.Stage.Open(str(root))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.GetStageUpAxis(source)
    mesh_path = str(Path(info.skel_root).parent / "Garments" / template.name)
    prim = stage.GetPrimAtPath(mesh_path)
    assert prim.IsDefined() and prim.IsA(UsdGeom.Mesh)
    assert not prim.GetPath().HasPrefix(info.skel_root)
    assert "GarmentAPI" in prim.GetAppliedSchemas()
    assert prim.GetAttribute("garment:method").Get() == "lbs"
    assert [str(p) for p in prim.GetRelationship("garment:body").GetTargets()] == [info.skeleton]
    mesh = UsdGeom.Mesh(prim)
    assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    assert len(mesh.GetNormalsAttr().Get(motion.time_codes[3])) == len(template.vertices)
    uv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    assert uv.GetInterpolation() == UsdGeom.Tokens.vertex
    assert len(mesh.GetExtentAttr().GetTimeSamples()) == motion.num_frames

    t = float(motion.time_codes[5])
    body_box = _bounds(stage, info.skel_root, t)
    garment_box = _bounds(stage, mesh_path, t)
    whole = _bounds(stage, "/", t)
    for box in (body_box, garment_box):
        assert not box.IsEmpty()
        assert whole.Contains(box)
    # The garment (a torso top) sits inside the body's box, in the same place.
    assert body_box.Contains(garment_box)


def test_value_clips_read_back_as_the_plain_layer(
    amass_layer: Path, tmp_path: Path, body_model: BodyModel
) -> None:
    template = torso_template(body_model)
    plain, clipped = tmp_path / "plain.usda", tmp_path / "clipped.usd"
    dress(amass_layer, plain, method="lbs", template=template)
    result = dress(
        amass_layer, clipped, method="lbs", template=template, clip_threshold=10,
        root_layer=tmp_path / "r.usda",
    )  # fmt: skip
    clip_dir = tmp_path / "clipped.clips"
    assert result.outputs == [clipped, clip_dir, tmp_path / "r.usda"]
    assert sorted(p.name for p in clip_dir.iterdir()) == [
        "clip_0000.usdc",
        "manifest.usda",
        "topology.usdc",
    ]
    assert validate_layer(clipped) == []
    assert validate_layer(tmp_path / "r.usda") == []
    a, fa, ia = read_garment_layer(plain)
    b, fb, ib = read_garment_layer(clipped)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(fa, fb)
    np.testing.assert_array_equal(ia.time_codes, ib.time_codes)


def test_dress_in_small_chunks_writes_the_same_garment(
    amass_layer: Path, tmp_path: Path, body_model: BodyModel
) -> None:
    template = torso_template(body_model)
    whole, chunked = tmp_path / "whole.usdc", tmp_path / "chunked.usdc"
    done: list[int] = []
    dress(amass_layer, whole, template=template, method="lbs")
    result = dress(amass_layer, chunked, template=template, method="lbs", frames_per_chunk=5,
                   clip_threshold=10, progress=done.append)  # fmt: skip
    assert done == [5, 10, 12] and result.outputs == [chunked, tmp_path / "chunked.clips"]
    # Same frames; only float rounding of the batched posing differs.
    a, b = read_garment_layer(whole)[0], read_garment_layer(chunked)[0]
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_several_clips_and_relative_paths(tmp_path: Path, body_model: BodyModel) -> None:
    motion = random_motion(frames=7)
    source = tmp_path / "in" / "body.usda"
    source.parent.mkdir()
    write_body_layer(source, motion, body_model, with_mesh=False)
    _, info = read_smpl_motion(source, body_model)
    frames = garment_layer.GarmentFrames(
        "tshirt", "tshirt", np.array([[0, 1, 2]]), np.zeros((3, 2)),
        np.random.default_rng(0).normal(size=(7, 3, 3)), "lbs", "m", "1", body_model.name,
    )  # fmt: skip
    out = tmp_path / "out" / "g.usdc"
    out.parent.mkdir()
    garment_layer.write_garment_layer(
        out, info, [frames], motion.time_codes, clip_threshold=1, clip_frames=3,
        root_layer=tmp_path / "root.usda",
    )  # fmt: skip
    assert len(list((tmp_path / "out" / "g.clips").glob("clip_*.usdc"))) == 3
    text = Sdf.Layer.FindOrOpen(str(tmp_path / "root.usda")).ExportToString()
    assert "./out/g.usdc" in text and "./in/body.usda" in text
    points, _, _ = read_garment_layer(out)
    np.testing.assert_allclose(points, frames.points, atol=1e-6)


@pytest.mark.parametrize("clip_threshold", [1, garment_layer.CLIP_THRESHOLD])
def test_streamed_chunks_write_the_same_layer(
    tmp_path: Path, body_model: BodyModel, clip_threshold: int
) -> None:
    motion = random_motion(frames=11)
    source = tmp_path / "body.usda"
    write_body_layer(source, motion, body_model, with_mesh=False)
    _, info = read_smpl_motion(source, body_model)
    points = np.random.default_rng(1).normal(size=(11, 3, 3))
    frames = garment_layer.GarmentFrames(
        "tshirt", "tshirt", np.array([[0, 1, 2]]), np.zeros((3, 2)), points, "lbs", "m", "1",
        body_model.name,
    )  # fmt: skip
    settings = {"clip_threshold": clip_threshold, "clip_frames": 4}
    whole, streamed = tmp_path / "whole.usdc", tmp_path / "streamed.usdc"
    garment_layer.write_garment_layer(whole, info, [frames], motion.time_codes, **settings)
    with garment_layer.GarmentLayerWriter(
        streamed, info, [frames], motion.time_codes, **settings
    ) as writer:
        for s, e in ((0, 1), (1, 6), (6, 7), (7, 11)):  # uneven, across clip boundaries
            writer.add([points[s:e]])
            assert not streamed.exists()
    a, _, ia = read_garment_layer(whole)
    b, _, ib = read_garment_layer(streamed)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ia.time_codes, ib.time_codes)
    if clip_threshold == 1:
        names = sorted(p.name for p in (tmp_path / "streamed.clips").iterdir())
        assert names == sorted(p.name for p in (tmp_path / "whole.clips").iterdir())
        assert len([n for n in names if n.startswith("clip_")]) == 3
    # Fewer frames than time codes: an error, and nothing written.
    before = set(tmp_path.iterdir())
    short = garment_layer.GarmentLayerWriter(
        tmp_path / "short.usdc", info, [frames], motion.time_codes, **settings
    )
    with pytest.raises(ValueError, match="10 frames written for 11 time codes"), short as writer:
        writer.add([points[:10]])
    assert set(tmp_path.iterdir()) == before


def test_failed_write_leaves_no_files(
    amass_layer: Path, tmp_path: Path, body_model: BodyModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    template = torso_template(body_model)
    before = set(tmp_path.iterdir())
    calls = []

    def failing_export(layer, path):
        calls.append(path)
        if len(calls) == 3:
            raise OSError("disk full")
        layer.Export(str(path))

    monkeypatch.setattr(garment_layer, "_export", failing_export)
    with pytest.raises(OSError, match="disk full"):
        dress(amass_layer, tmp_path / "g.usdc", method="lbs", template=template,
              clip_threshold=10, root_layer=tmp_path / "root.usda")  # fmt: skip
    assert set(tmp_path.iterdir()) == before


def _rig_garment(
    tmp_path: Path, name: str, motion, body: BodyModel, style: RigStyle, template
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dress a rig whose ``/World`` (an ancestor of the SkelRoot and of the garments) is moved
    by 3 m, -1 m, 2 m and turned 30° about up, in the rig's axes and units. Returns canonical
    points, world points (composed over the rig) and the stage's canonical-to-world matrix."""
    rig = tmp_path / f"{name}.usda"
    out, root = tmp_path / f"{name}_g.usdc", tmp_path / f"{name}_r.usda"
    write_rig(rig, motion, body, style)
    stage = Usd.Stage.Open(str(rig))
    to_stage = canonical_to_world_matrix(style.up_axis, style.meters_per_unit)
    xform = UsdGeom.Xformable(stage.GetPrimAtPath("/World"))
    xform.AddTranslateOp().Set(Gf.Vec3d(*(np.array([3.0, -1.0, 2.0]) @ to_stage[:3, :3])))
    if style.up_axis == "Y":
        xform.AddRotateYOp().Set(30.0)
    else:
        xform.AddRotateZOp().Set(30.0)
    stage.Save()
    dress(rig, out, method="lbs", template=template, root_layer=root)
    canonical, _, info = read_garment_layer(out)
    composed = Usd.Stage.Open(str(root))
    mesh = composed.GetPrimAtPath(info.mesh)
    world = []
    for t in info.time_codes.tolist():
        local = np.asarray(UsdGeom.Mesh(mesh).GetPointsAttr().Get(t), dtype=np.float64)
        m = np.asarray(UsdGeom.XformCache(t).GetLocalToWorldTransform(mesh))
        world.append(local @ m[:3, :3] + m[3, :3])
    return canonical, np.stack(world), to_stage


def test_unusual_rigs_give_the_same_garment(tmp_path: Path, body_model: BodyModel) -> None:
    motion = random_motion(frames=6, fps=24.0)
    template = torso_template(body_model)
    tol = 1e-4 * float(heights(body_model, torch.zeros(1, 10))[0])
    plain, plain_world, _ = _rig_garment(
        tmp_path, "plain", motion, body_model, RigStyle(), template
    )
    np.testing.assert_allclose(plain_world, plain, atol=tol)
    odd = dict(up_axis="Z", meters_per_unit=0.01, orient_seed=4, shuffle_seed=5, fingers=True,
               prefix="m_avg_", short_names=True)  # fmt: skip
    for name, step in (("odd24", 1), ("odd120", 5)):
        style = RigStyle(step=step, **odd)
        canonical, world, to_stage = _rig_garment(
            tmp_path, name, motion, body_model, style, template
        )
        assert len(canonical) == (len(plain) - 1) * step + 1
        np.testing.assert_allclose(canonical[::step], plain, atol=tol)
        # The mesh lands at the same place in the stage's world, whatever /World's transform.
        np.testing.assert_allclose(world, canonical @ to_stage[:3, :3], atol=tol * 100)


def test_proxy_mesh_is_the_garment_carried_to_a_lower_lod(
    tmp_path: Path, amass_layer: Path
) -> None:
    from usd_garment.garment.library import load_template
    from usd_garment.garment.lod import carry_to_lod

    out = tmp_path / "g.usda"
    args = ["dress", str(amass_layer), "-o", str(out), "--method", "lbs", "--lod", "medium"]
    result = CliRunner().invoke(main, [*args, "--proxy", "low"])
    assert result.exit_code == 0, result.output
    points, _, info = read_garment_layer(out)  # the proxy is not a garment of its own
    assert info.mesh.endswith("/tshirt")
    assert points.shape[1] == len(load_template("tshirt", "medium").vertices)
    stage = Usd.Stage.Open(str(out))
    garment = stage.GetPrimAtPath(info.mesh)
    proxy = stage.GetPrimAtPath(info.mesh + "_proxy")
    assert UsdGeom.Imageable(garment).GetPurposeAttr().Get() == UsdGeom.Tokens.render
    assert UsdGeom.Imageable(proxy).GetPurposeAttr().Get() == UsdGeom.Tokens.proxy
    assert UsdGeom.Imageable(garment).GetProxyPrimRel().GetTargets() == [proxy.GetPath()]
    assert validate_layer(out) == []
    attr = UsdGeom.Mesh(proxy).GetPointsAttr()
    local = np.stack([np.asarray(attr.Get(t)) for t in info.time_codes.tolist()])
    m = info.canonical_to_local
    carried = carry_to_lod(points, "tshirt", "medium", "low") @ m[:3, :3] + m[3, :3]
    np.testing.assert_allclose(local, carried, atol=1e-5)
    bad = CliRunner().invoke(main, [*args[:-1], "low", "--proxy", "low"])
    assert bad.exit_code == 1 and "lower level of detail" in bad.output


@pytest.mark.parametrize("clip_threshold", [1, garment_layer.CLIP_THRESHOLD])
def test_lod_variant_set_holds_every_coarser_level(
    tmp_path: Path, amass_layer: Path, clip_threshold: int
) -> None:
    from usd_garment.garment.library import load_template
    from usd_garment.garment.lod import carry_to_lod

    out = tmp_path / "g.usdc"
    dress(amass_layer, out, method="lbs", lod="medium", lod_variants=True, proxy_lod="low",
          clip_threshold=clip_threshold)  # fmt: skip
    points, _, info = read_garment_layer(out)  # the default variant: the computed level
    assert points.shape[1] == len(load_template("tshirt", "medium").vertices)
    assert validate_layer(out) == []
    stage = Usd.Stage.Open(str(out))
    garment = stage.GetPrimAtPath(info.mesh)
    variants = garment.GetVariantSet("lod")
    assert sorted(variants.GetVariantNames()) == ["low", "medium"]
    assert variants.GetVariantSelection() == "medium"
    variants.SetVariantSelection("low")  # (edits the session's root layer, not the file)
    mesh = UsdGeom.Mesh(garment)
    low = load_template("tshirt", "low")
    assert len(mesh.GetFaceVertexCountsAttr().Get()) == len(low.faces)
    local = np.stack([np.asarray(mesh.GetPointsAttr().Get(t)) for t in info.time_codes.tolist()])
    m = info.canonical_to_local
    carried = carry_to_lod(points, "tshirt", "medium", "low") @ m[:3, :3] + m[3, :3]
    np.testing.assert_allclose(local, carried, atol=1e-5)
    normals = np.asarray(mesh.GetNormalsAttr().Get(info.time_codes[-1]))
    assert normals.shape == (len(low.vertices), 3)
    assert UsdGeom.Imageable(garment).GetProxyPrimRel().GetTargets() == [
        stage.GetPrimAtPath(info.mesh + "_proxy").GetPath()
    ]
    with pytest.raises(ValueError, match="level of detail below 'low'"):
        dress(amass_layer, tmp_path / "x.usdc", method="lbs", lod="low", lod_variants=True)


def test_eval_measures_a_lod_variant_without_changing_the_file(
    tmp_path: Path, amass_layer: Path
) -> None:
    """``eval --lod-variant`` reads the named variant of a ``dress --lod-variants`` layer (from
    the stage's session layer: the file keeps its bytes); a variant the layer lacks, or a layer
    without variants, is a one-line error."""
    from usd_garment.garment.library import load_template
    from usd_garment.garment.lod import carry_to_lod

    out, plain = tmp_path / "g.usdc", tmp_path / "plain.usdc"
    dress(amass_layer, out, method="lbs", lod="medium", lod_variants=True)
    dress(amass_layer, plain, method="lbs", lod="medium")
    before = hashlib.sha256(out.read_bytes()).hexdigest()
    medium, _, _ = read_garment_layer(out)
    low, faces, _ = read_garment_layer(out, lod="low")
    assert len(faces) == len(load_template("tshirt", "low").faces)
    np.testing.assert_allclose(low, carry_to_lod(medium, "tshirt", "medium", "low"), atol=1e-5)
    args = ["eval", str(out), "--body", str(amass_layer), "--json"]
    result = CliRunner().invoke(main, [*args, "--lod-variant", "low"])
    assert result.exit_code == 0, result.output
    assert len(json.loads(result.output)["time_codes"]) == len(medium)
    assert hashlib.sha256(out.read_bytes()).hexdigest() == before
    for layer, level in ((out, "high"), (plain, "low")):
        bad = CliRunner().invoke(main, ["eval", str(layer), "--body", str(amass_layer),
                                        "--lod-variant", level])  # fmt: skip
        assert bad.exit_code == 1 and f"no 'lod' variant '{level}'" in bad.output
        assert len(bad.output.strip().splitlines()) == 1


def test_batched_vertex_normals_match_one_frame_at_a_time() -> None:
    from usd_garment.garment.library import load_template
    from usd_garment.garment.mesh_ops import vertex_normals

    low = load_template("tshirt", "low")
    rng = np.random.default_rng(0)
    frames = low.vertices[None] + 0.01 * rng.standard_normal((5, *low.vertices.shape))
    batched = garment_layer.vertex_normals(frames.astype(np.float32), low.faces)
    assert batched.shape == frames.shape and batched.dtype == np.float32
    for t, points in enumerate(frames):
        np.testing.assert_allclose(batched[t], vertex_normals(points, low.faces), atol=1e-4)
