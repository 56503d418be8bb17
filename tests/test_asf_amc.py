"""ASF/AMC import: a real CMU capture in its own format lands on the body as the database's BVH
conversion of it does, the Acclaim conventions (bone axes, dof order, radians) on a small rig,
the reader behind ``dataset make --capture``, and bad input."""

from __future__ import annotations

import gzip
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from tests.script_calls import ROOT, calls_on_base, copied_from_base
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.eval.evaluate import posed_body_vertices
from usd_garment.motion.asf_amc import (
    AMC_FPS,
    asf_clip,
    find_asf,
    is_amc_path,
    parse_amc,
    parse_asf,
    read_amc,
)
from usd_garment.motion.bvh import forward_kinematics, load_bvh
from usd_garment.motion.motion_file import read_motion_file

HERE = Path(__file__).parent
AMC = HERE / "data" / "asf" / "02_01.amc"
ASF = HERE / "data" / "asf" / "02.asf"
#: The same capture in the database's BVH conversion, whose frame 0 is an added T-pose.
BVH = HERE.parent / "examples" / "mocap" / "cmu_02_01.bvh.xz"


@pytest.mark.parametrize("collars", ["rest", "aimed"])
def test_amc_capture_lands_as_its_bvh_conversion(body_model: BodyModel, collars: str) -> None:
    """CMU 02_01 read from ASF/AMC poses the body within 0.01 mm of the same frames of its BVH
    conversion (a conversion made elsewhere: the same rotations, the same units detected)."""
    amc, amc_info = load_bvh(AMC, body_model, collars=collars)
    bvh, bvh_info = load_bvh(BVH, body_model, frames=(1, 41), collars=collars)
    assert amc.num_frames == bvh.num_frames == 40 and amc.fps == bvh.fps == AMC_FPS
    assert amc_info.units == bvh_info.units == "cmu" and amc_info.joint_map == bvh_info.joint_map
    gap = np.linalg.norm(
        posed_body_vertices(body_model, amc) - posed_body_vertices(body_model, bvh), axis=-1
    )
    assert gap.max() < 1e-5, gap.max()


def test_import_through_the_cli_and_as_a_dataset_capture(
    body_model: BodyModel, tmp_path: Path
) -> None:
    """``import-bvh`` takes an AMC file (its ASF found beside it, compressed too) and
    ``read_motion_file`` (``dataset make --capture``, ``motion poses``) reads it."""
    folder = tmp_path / "02"
    folder.mkdir()
    shutil.copy(ASF, folder / "02.asf")
    packed = folder / "02_01.amc.gz"
    packed.write_bytes(gzip.compress(AMC.read_bytes()))
    out = tmp_path / "walk.usda"
    args = ["import-bvh", str(packed), "-o", str(out), "--fps", "30", "--no-mesh", "--json"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["frames"] == 10 and summary["source_fps"] == AMC_FPS
    assert len(summary["joint_map"]) == 24 and summary["joint_map"]["spine3"] == "Spine1"
    assert is_amc_path(packed) and is_amc_path("A.AMC") and not is_amc_path("a.asf")
    assert find_asf(packed) == folder / "02.asf"
    motion = read_motion_file(AMC, body_model)
    assert motion.num_frames == 40 and motion.fps == AMC_FPS


RIG = """:version 1.10
:units
  length 1.0
  angle {angle}
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name upper
     direction 1 0 0
     length 2
     axis 0 0 {axis} XYZ
    dof {dofs}
  end
  begin
     id 2
     name lower
     direction 1 0 0
     length 1
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root upper
    upper lower
  end
"""


def test_bone_axes_dof_order_and_radians() -> None:
    """A bone's rotation is ``C · M · C⁻¹``: ``C`` its axis, ``M`` its dofs applied in the listed
    order about fixed axes; AMC values in radians where the file says ``:RADIANS``."""
    axis = 90.0  # C turns x onto y: the bone's rx turns about the world's y
    skeleton = parse_asf(RIG.format(angle="deg", axis=axis, dofs="rz rx"), "rig.asf")
    angles = (30.0, 40.0)  # rz first, then rx
    amc = f":DEGREES\n1\nroot 1 2 3 0 0 0\nupper {angles[0]} {angles[1]}\n"
    rotations, positions = forward_kinematics(asf_clip(skeleton, parse_amc(amc, skeleton)))
    c = Rotation.from_euler("z", axis, degrees=True).as_matrix()
    m = Rotation.from_euler("zx", angles, degrees=True).as_matrix()  # extrinsic: z, then x
    np.testing.assert_allclose(rotations[0, 1], c @ m @ c.T, atol=1e-12)
    np.testing.assert_allclose(positions[0, 0], (1, 2, 3))
    np.testing.assert_allclose(positions[0, 2], np.array([1, 2, 3]) + c @ m @ c.T @ (2, 0, 0))
    radians = parse_asf(RIG.format(angle="rad", axis=np.pi / 2, dofs="rz rx"), "rig.asf")
    amc_rad = f":RADIANS\n1\nroot 1 2 3 0 0 0\nupper {np.radians(30)} {np.radians(40)}\n"
    again = forward_kinematics(asf_clip(radians, parse_amc(amc_rad, radians)))[0]
    np.testing.assert_allclose(again[0, 1], rotations[0, 1], atol=1e-12)


def _copy(tmp: Path, amc: str | None = None, asf: str | None = None) -> Path:
    """``tmp/02_01.amc`` beside ``tmp/02.asf``: the test capture, or the texts given."""
    (tmp / "02.asf").write_text(asf if asf is not None else ASF.read_text())
    (tmp / "02_01.amc").write_text(amc if amc is not None else AMC.read_text())
    return tmp / "02_01.amc"


def _edit_amc(old: str, new: str, count: int = 1) -> Callable[[Path], Path]:
    return lambda tmp: _copy(tmp, amc=AMC.read_text().replace(old, new, count))


def _no_asf(tmp: Path) -> Path:
    (tmp / "02_01.amc").write_text(AMC.read_text())
    return tmp / "02_01.amc"


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (_no_asf, "no skeleton: expected 02.asf"),
        (_edit_amc("\nlowerback", "\nlowback"), "unknown bone 'lowback'"),
        (_edit_amc("\nrtibia 11.5302", "\nrtibia 11.5302 2"), "2 values for 'rtibia'"),
        (_edit_amc("\nltoes -10.2227", "\n"), "frame 1 lacks the bone 'ltoes'"),
        (_edit_amc("\nrtibia 11.5302", "\nrtibia nan"), "NaN or infinite"),
        (lambda t: _copy(t, amc=":DEGREES\n"), "has no frames"),
        (lambda t: _copy(t, asf="hello\n"), "not an ASF file"),
        (lambda t: _copy(t, asf=ASF.read_text().replace("root lhipjoint", "root")),
         "bones outside the hierarchy: lhipjoint"),
        (lambda t: _copy(t, asf=ASF.read_text().replace("TX TY TZ", "TX TY TW")),
         "unknown or repeated degree of freedom in 'TX TY TW RX RY RZ'"),
        (lambda t: _copy(t, asf=ASF.read_text().replace("dof rx ry rz", "dof rx rx rz", 1)),
         "unknown or repeated degree of freedom in 'rx rx rz'"),
    ],
    ids=["no-asf", "unknown-bone", "value-count", "missing-bone", "nan", "no-frames",
         "not-asf", "orphan", "root-order", "repeated-dof"],
)  # fmt: skip
def test_bad_input_gives_one_line_and_no_output(
    tmp_path: Path, make: Callable[[Path], Path], expected: str
) -> None:
    source = make(tmp_path)
    before = {p: p.read_bytes() for p in tmp_path.iterdir()}
    result = CliRunner().invoke(main, ["import-bvh", str(source), "-o", str(tmp_path / "b.usda")])
    assert result.exit_code == 1
    message = result.stderr.strip()
    assert message.startswith("Error:") and "\n" not in message, message
    assert expected in message, message
    assert {p: p.read_bytes() for p in tmp_path.iterdir()} == before  # input untouched, no output


def test_the_amc_data_script(tmp_path: Path) -> None:
    """``examples/train/data_amc.sh tshirt OUT BASE`` imports the four subject-02 captures of
    ``examples/mocap/asf`` (frames inside each file: 1,846 at 30 fps, as ``docs/learning.md``
    says), makes the train-only set amc4 of them, and projects it onto copies of BASE's two
    canonical sets."""
    calls = calls_on_base("data_amc.sh", "scratch/amc", tmp_path)
    imports = [a for a in calls if a[0] == "import-bvh"]
    names = [Path(a[1]).name for a in imports]
    assert names == [f"02_{n}.amc.xz" for n in ("05", "06", "07", "10")]
    assert all(a[a.index("--collars") + 1] == "rest" for a in imports)
    frames = 0
    for a in imports:
        first, end = (int(v) for v in a[a.index("--frames") + 1].split(":"))
        clip = read_amc(ROOT / a[1])
        assert 0 <= first < end <= clip.num_frames
        frames += len(range(first, end, 4))  # 120 fps to 30
    assert frames == 1846
    (make,) = [a for a in calls if a[:2] == ["dataset", "make"]]
    captured = [make[i + 1] for i, w in enumerate(make) if w == "--capture"]
    assert captured == [f"{a[a.index('-o') + 1]}:train" for a in imports]
    assert make[make.index("--motions") + 1] == "0" and make[make.index("--shapes") + 1] == "1"
    projected = [a[a.index("-o") + 1] for a in calls if a[0] == "project"]
    assert projected == [f"scratch/amc/canonical_tshirt_{n}.npz" for n in ("v4c", "v4cs")]
    assert copied_from_base(tmp_path, "scratch/amc")
