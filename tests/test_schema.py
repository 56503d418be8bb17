"""The codeless schema: registered at import, applied schemas round-trip, and files that use
them open where the plugin is absent."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import resources
from pathlib import Path

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdSkel

import usd_garment  # noqa: F401  (registers the schemas)
from usd_garment.usd.schema import (
    apply_garment,
    apply_smpl_body,
    read_betas,
    read_cuts,
    read_garment,
    read_smpl_body,
    register_schemas,
)


def test_schema_files_are_package_data() -> None:
    folder = resources.files("usd_garment.schemas")
    names = {p.name for p in folder.iterdir()}
    assert {"schema.usda", "generatedSchema.usda", "plugInfo.json"} <= names
    text = (folder / "plugInfo.json").read_text()
    info = json.loads("\n".join(ln for ln in text.splitlines() if not ln.startswith("#")))
    types = info["Plugins"][0]["Info"]["Types"]
    assert types["UsdGarmentSmplBodyAPI"]["schemaKind"] == "singleApplyAPI"


def test_registered_definitions() -> None:
    register_schemas()  # idempotent
    registry = Usd.SchemaRegistry()
    smpl = registry.FindAppliedAPIPrimDefinition("SmplBodyAPI")
    garment = registry.FindAppliedAPIPrimDefinition("GarmentAPI")
    assert smpl is not None and garment is not None
    assert {"smpl:betas", "smpl:gender", "smpl:model", "smpl:cuts"} <= set(smpl.GetPropertyNames())
    assert "garment:body" in garment.GetPropertyNames()
    assert smpl.GetAttributeFallbackValue("smpl:gender") == "neutral"


def test_applied_schemas_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "tagged.usda"
    stage = Usd.Stage.CreateNew(str(path))
    skel = UsdSkel.Skeleton.Define(stage, "/Char/Body/Skel").GetPrim()
    mesh = UsdGeom.Mesh.Define(stage, "/Char/Garments/tshirt").GetPrim()
    betas = np.linspace(-2, 2, 16)
    apply_smpl_body(skel, betas, "female", "smplh", "1.1", cuts=(45.0, 101.5))
    apply_garment(mesh, "tshirt", "learned", "tshirt-v1.pt", "3", "default", skel.GetPath(), "{}")
    stage.GetRootLayer().Save()

    again = Usd.Stage.Open(str(path))
    skel, mesh = (
        again.GetPrimAtPath("/Char/Body/Skel"),
        again.GetPrimAtPath("/Char/Garments/tshirt"),
    )
    assert skel.HasAPI("SmplBodyAPI") and mesh.HasAPI("GarmentAPI")
    np.testing.assert_allclose(read_betas(skel), betas, atol=1e-6)
    assert read_smpl_body(skel) == {"gender": "female", "model": "smplh", "modelVersion": "1.1"}
    assert read_garment(mesh) == {
        "type": "tshirt", "method": "learned", "model": "tshirt-v1.pt", "modelVersion": "3",
        "bodyModel": "default", "solverSettings": "{}", "body": "/Char/Body/Skel",
    }  # fmt: skip
    np.testing.assert_array_equal(read_cuts(skel), [45.0, 101.5])
    assert read_betas(again.GetPrimAtPath("/Char")) is None
    assert read_cuts(again.GetPrimAtPath("/Char")) is None
    for name in ("smpl:betas", "smpl:cuts"):
        attr = skel.GetAttribute(name)
        assert attr.GetVariability() == Sdf.VariabilityUniform and not attr.IsCustom()


def test_opens_without_the_plugin(tmp_path: Path) -> None:
    """A fresh interpreter that never imports usd_garment reads the file and its values."""
    path = tmp_path / "tagged.usdc"
    stage = Usd.Stage.CreateNew(str(path))
    skel = UsdSkel.Skeleton.Define(stage, "/Skel").GetPrim()
    apply_smpl_body(skel, np.arange(10.0), "male", "smpl")
    stage.GetRootLayer().Save()
    code = (
        "import sys\n"
        "from pxr import Usd\n"
        "s = Usd.Stage.Open(sys.argv[1])\n"
        "p = s.GetPrimAtPath('/Skel')\n"
        "assert 'usd_garment' not in sys.modules\n"
        "assert Usd.SchemaRegistry().FindAppliedAPIPrimDefinition('SmplBodyAPI') is None\n"
        "schemas = p.GetMetadata('apiSchemas').GetAddedOrExplicitItems()\n"
        "print(list(schemas), list(p.GetAttribute('smpl:betas').Get()),"
        " p.GetAttribute('smpl:gender').Get())\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True,
        cwd=tmp_path,
    )  # fmt: skip
    assert (
        out.stdout.strip()
        == "['SmplBodyAPI'] [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0] male"
    )


def test_cuts_authored_over_a_shot_reach_the_reader(tmp_path: Path, body_model) -> None:
    """A studio declares the cuts of a shot in a layer of its own that sublayers the animation
    (the animation's file unchanged): the composed skeleton's ``smpl:cuts`` are the motion's
    ``cut_times``, and ``dress`` of that layer reports them."""
    from usd_garment.dress import dress
    from usd_garment.motion.procedural import make_motion
    from usd_garment.usd.body_layer import SKELETON_PATH, write_body_layer
    from usd_garment.usd.read import read_smpl_motion

    shot = tmp_path / "shot.usdc"
    write_body_layer(shot, make_motion("walk", 6, body=body_model), body_model)
    before = shot.read_bytes()
    edit = tmp_path / "edit.usda"
    stage = Usd.Stage.CreateNew(str(edit))
    stage.GetRootLayer().subLayerPaths.append(shot.name)
    stage.OverridePrim(SKELETON_PATH).CreateAttribute(
        "smpl:cuts",
        Sdf.ValueTypeNames.DoubleArray,
        custom=False,
        variability=Sdf.VariabilityUniform,
    ).Set([3.0, 2.5])
    stage.GetRootLayer().Save()
    assert read_smpl_motion(shot, body_model)[0].cut_times == ()
    assert read_smpl_motion(edit, body_model)[0].cut_times == (2.5, 3.0)
    result = dress(edit, tmp_path / "g.usdc", method="lbs", lod="low")
    assert result.cuts == [3.0] and shot.read_bytes() == before
