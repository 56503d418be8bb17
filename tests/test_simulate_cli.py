"""``usd-garment simulate`` and ``garment drape``: a simulated garment layer with GarmentAPI method
"simulation", its solver settings and per-frame quality, bad frames kept unless ``--strict``,
nothing written when the simulation fails, and draped templates that keep their rest lengths
and stay outside the rest body."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from pxr import Usd

import usd_garment.cli.simulate as simulate_cli
from usd_garment.body.io import load_body_model
from usd_garment.cli.main import main
from usd_garment.eval.body_distance import BodySurface, signed_distance
from usd_garment.garment.library import find_draped, load_template
from usd_garment.garment.template import GARMENT_NAMES, LODS
from usd_garment.methods.simulation import SimulationMethod
from usd_garment.motion.sequence import SmplMotion
from usd_garment.sim.checks import CheckLimits, unique_edges
from usd_garment.sim.cloth import ITERATIONS, SUBSTEPS
from usd_garment.sim.drape import rest_body
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.garment_read import garment_meshes, read_garment_layer
from usd_garment.usd.schema import read_garment

pytest.importorskip("newton")


def _arms_down(frames: int, dash_at: int | None = None) -> SmplMotion:
    """Both arms lowered from the T-pose by up to 0.3 rad; with ``dash_at`` the body dashes
    sideways from that frame on at 30 m/s, 1 m a frame: no garment can follow, and no single
    step stands out from the steps beside it, so the motion has no cut (a teleport or a
    declared cut would be simulated as one motion moved, or from a lead-in of its own)."""
    w = np.linspace(0.0, 0.3, frames, dtype=np.float32)
    pose = np.zeros((frames, 24, 3), dtype=np.float32)
    pose[:, 16, 2], pose[:, 17, 2] = -w, w
    trans = np.zeros((frames, 3), dtype=np.float32)
    if dash_at is not None:
        trans[dash_at:, 0] = np.arange(1, frames - dash_at + 1)
    return SmplMotion(np.zeros(10, np.float32), pose, trans, 30.0)


def _run(args: list[object]) -> tuple[int, str]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(result.exception, AssertionError)
    return result.exit_code, result.output


def test_simulate_writes_a_simulation_layer(tmp_path: Path) -> None:
    body_path, out = tmp_path / "body.usdc", tmp_path / "sim.usdc"
    write_body_layer(body_path, _arms_down(4), load_body_model(None))
    code, output = _run(["simulate", body_path, "-o", out, "--lod", "low", "--json"])
    assert code == 0, output
    summary = json.loads(output[output.index("{") :])
    assert summary["method"] == "simulation" and summary["frames"] == 4
    points, faces, info = read_garment_layer(out)
    template = load_template("tshirt", "low")
    assert points.shape == (4, len(template.vertices), 3) and np.isfinite(points).all()
    assert np.array_equal(faces, template.faces) and info.method == "simulation"
    stage = Usd.Stage.Open(str(out))
    prim = garment_meshes(stage)[0]
    assert "GarmentAPI" in prim.GetAppliedSchemas()
    values = read_garment(prim)
    assert values["method"] == "simulation"
    settings = json.loads(values["solverSettings"])
    assert (settings["substeps"], settings["iterations"]) == (SUBSTEPS, ITERATIONS)
    assert settings["status"] == "ok" and settings["newton"] and settings["retries"] == {}
    assert settings["material"]["area_density"] == pytest.approx(0.20022)
    assert settings["max_distance_m"] < 0.15 and settings["penetrating_share_max"] <= 0.005
    assert settings["strict"] is False and settings["bad_frames"] == 0
    assert settings["contact"]["release"] == "retry" and settings["released_frames"] == 0
    assert settings["version"] == SimulationMethod.version  # which simulator made the layer
    per_frame = settings["per_frame"]
    for key in ("inside_forced", "inside_elsewhere", "stretch_p99", "stretch_max", "projected",
                "substeps", "bad", "released"):  # fmt: skip
        assert len(per_frame[key]) == 4, key
    pairs = zip(per_frame["stretch_p99"], per_frame["stretch_max"], strict=True)
    assert all(p99 <= largest for p99, largest in pairs)
    assert settings["stretch_max"] == pytest.approx(max(per_frame["stretch_max"]), abs=1e-4)
    assert 0.0 <= settings["projected_share_mean"] <= settings["projected_share_max"] <= 1.0
    assert per_frame["bad"] == [0] * 4 and per_frame["substeps"] == [SUBSTEPS] * 4
    assert max(per_frame["inside_elsewhere"]) <= settings["inside_elsewhere_share_max"] + 1e-6
    assert 1.0 < settings["lead_in_stretch_p99_first"] < 1.06
    assert summary["simulation"]["per_frame"] == per_frame


class _TightMethod(SimulationMethod):
    """The simulation with a stretch limit no frame meets, no retries and a 2-frame lead-in."""

    def __init__(self, substeps: int, iterations: int, material: object, **kwargs: object) -> None:
        kwargs.update(max_substeps=substeps, lead_in=2, settle=0, max_bad_run=100,
                      limits=CheckLimits(max_stretch=1.0))  # fmt: skip
        super().__init__(substeps, iterations, material, **kwargs)  # type: ignore[arg-type]


def test_bad_frames_are_kept_and_flagged_unless_strict(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(simulate_cli, "SimulationMethod", _TightMethod)
    body_path, out = tmp_path / "body.usdc", tmp_path / "sim.usdc"
    write_body_layer(body_path, _arms_down(3), load_body_model(None))
    code, output = _run(["simulate", body_path, "-o", out, "--lod", "low"])
    assert code == 0, output
    assert "3 released from the arms, 3 bad frames kept" in output  # each with a released try
    stage = Usd.Stage.Open(str(out))
    settings = json.loads(read_garment(garment_meshes(stage)[0])["solverSettings"])
    assert settings["status"] == "ok" and settings["bad_frames"] == 3
    assert settings["per_frame"]["bad"] == [1, 1, 1] and settings["lead_in_bad_frames"] == 2
    assert settings["per_frame"]["released"] == [1, 1, 1]
    never = tmp_path / "never.usdc"
    code, output = _run(["simulate", body_path, "-o", never, "--lod", "low", "--release", "never"])
    assert code == 0 and "0 released from the arms, 3 bad frames kept" in output, output
    assert read_garment_layer(out)[2].flagged.tolist() == [True] * 3  # what training skips
    strict_out = tmp_path / "strict.usdc"
    code, output = _run(["simulate", body_path, "-o", strict_out, "--lod", "low", "--strict"])
    assert code != 0
    error = [line for line in output.splitlines() if line.startswith("Error")]
    assert len(error) == 1, output
    assert "simulation failed at lead-in frame 0: edge stretch p99" in error[0]
    assert not strict_out.exists()


def test_failed_simulation_writes_nothing(tmp_path: Path) -> None:
    """A body that dashes off at frame 3 fails the simulation with one clear line naming that
    frame of the motion, though a declared cut at frame 1 makes it the second run's frame 2
    (each run between restarts is simulated from a lead-in of its own); nothing is written,
    and the input is left as it was."""
    folder = tmp_path / "in"
    folder.mkdir()
    body_path = folder / "body.usdc"
    dashing = replace(_arms_down(6, dash_at=3), cut_times=(1.0,))
    write_body_layer(body_path, dashing, load_body_model(None))
    out = tmp_path / "out" / "sim.usdc"
    out.parent.mkdir()
    code, output = _run(["simulate", body_path, "-o", out, "--lod", "low"])
    assert code != 0
    error = [line for line in output.splitlines() if line.startswith("Error")]
    assert len(error) == 1 and "simulation failed at motion frame 3" in error[0], output
    assert "Traceback" not in output
    assert list(out.parent.iterdir()) == [] and list(folder.iterdir()) == [body_path]


def test_simulate_bad_material_is_one_line(tmp_path: Path) -> None:
    material = tmp_path / "silk.json"
    material.write_text('{"lame_mu": -1}')
    code, output = _run(["simulate", tmp_path / "b.usdc", "-o", tmp_path / "o.usdc",
                         "--material", material])  # fmt: skip
    assert code != 0 and "lame_mu" in output and "Traceback" not in output


def test_drape_keeps_rest_lengths_and_stays_outside(tmp_path: Path) -> None:
    code, output = _run(["garment", "drape", "tshirt", "--lod", "low", "-o", tmp_path, "--json"])
    assert code == 0, output
    report = json.loads(output[output.index("[") :])[0]
    assert report["settled"] and report["rest_length_error_median"] < 0.05
    assert report["inside_count"] == 0 and report["clearance_min_m"] > 0.0
    assert (tmp_path / "tshirt_low_draped.npz").is_file()


@pytest.mark.parametrize("name", GARMENT_NAMES)
@pytest.mark.parametrize("lod", list(LODS))
def test_committed_draped_templates(name: str, lod: str) -> None:
    body = load_body_model(None)
    template = load_template(name, lod)
    draped = load_template(name, lod, draped=True)
    assert find_draped(template, body) is not None
    assert np.array_equal(draped.faces, template.faces)
    edges = unique_edges(template.faces)

    def lengths(v: np.ndarray) -> np.ndarray:
        return np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)

    error = np.abs(lengths(draped.vertices) / lengths(template.vertices) - 1.0)
    assert np.median(error) < 0.05
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    sdf = signed_distance(draped.vertices[None], rest_body(body)[None], surface).distance
    assert (sdf >= 0).all()
    assert not np.allclose(draped.vertices, template.vertices)  # it did settle


@pytest.mark.slow
def test_a_capture_with_the_arms_as_captured_is_simulated(tmp_path: Path) -> None:
    """CMU 131_01 with the arms as captured (``--arm-clearance 0``), motion frames 45–70, where
    the left forearm passes into the hip: by default (the released try) the T-shirt is
    simulated with nothing inside elsewhere; without it the hem is caught and the sequence
    fails on its run of bad frames (about 50 s each, T-shirt high)."""
    source = Path(__file__).parents[2] / "shared" / "mocap" / "cmu_131_01.bvh"
    if not source.is_file():
        pytest.skip("the shared CMU clips are not beside the project")
    body = tmp_path / "arms.usdc"
    code, output = _run(["import-bvh", source, "-o", body, "--fps", 30, "--arm-clearance", 0])
    assert code == 0, output
    out = tmp_path / "sim.usdc"
    code, output = _run(["simulate", body, "-o", out, "--frames", "45:70", "--json"])
    assert code == 0, output
    settings = json.loads(output[output.index("{") :])["simulation"]
    assert settings["status"] == "ok" and settings["released_frames"] > 0
    assert settings["inside_elsewhere_share_max"] == 0.0 and settings["max_distance_m"] < 0.10
    assert settings["inside_forced_share_max"] > 0.01  # the forearm in the hip
    code, output = _run(["simulate", body, "-o", tmp_path / "never.usdc", "--frames", "45:70",
                         "--release", "never"])  # fmt: skip
    assert code != 0 and "where the pose presses a limb into it" in output, output
    assert not (tmp_path / "never.usdc").exists()
