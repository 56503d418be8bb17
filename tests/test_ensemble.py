"""A model of several members (an ensemble): ``train combine`` writes one, its garment is the
mean of its members' canonical garments, ``dress`` uses it like any model, mismatched models are
refused with nothing written, and a model directory of the first layout (one member) still
loads."""

from __future__ import annotations

import json
import os
import stat
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from pxr import Usd
from safetensors.torch import load_file, save_file
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from tests.models import untrained_model
from usd_garment.body.io import load_body_model
from usd_garment.body.model import BodyModel
from usd_garment.cli.main import main
from usd_garment.garment.library import load_template
from usd_garment.garment.template import GarmentTemplate
from usd_garment.methods.learned import LearnedMethod, predict_latents
from usd_garment.methods.learned_model import ModelError, load_learned_model, save_learned_model
from usd_garment.motion.cuts import motion_cuts, motion_restarts, root_cuts
from usd_garment.motion.procedural import make_motion
from usd_garment.motion.sequence import SmplMotion
from usd_garment.usd.body_layer import write_body_layer
from usd_garment.usd.garment_read import read_garment_layer


class SmoothedAlone(LearnedMethod):
    """The networks with the model's posed smoothing and no push: the smoothing alone."""

    smooths = True


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return load_body_model()


@pytest.fixture(scope="module")
def template() -> GarmentTemplate:
    return load_template("tshirt", "low")


def _run(args: list[object]) -> tuple[int, str]:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(result.exception, AssertionError)
    return result.exit_code, result.output


def _members(tmp_path: Path, body: BodyModel, template: GarmentTemplate) -> list[Path]:
    """Two saved single-member models of ``template`` drawn with seeds 0 and 1."""
    paths = [tmp_path / f"seed{seed}" for seed in (0, 1)]
    for seed, path in enumerate(paths):
        save_learned_model(path, untrained_model(body, template, seed))
    return paths


def test_combined_model_is_the_mean_of_its_members(tmp_path, body, template):
    first, second = _members(tmp_path, body, template)
    for path in (first, second):  # what 'train all' leaves beside a model
        (path / "curves.png").write_bytes(f"curves of {path.name}".encode())
        (path / "train.log").write_text(f"log of {path.name}\n")
    out = tmp_path / "ensemble"
    code, output = _run(["train", "combine", first, second, "--out", out])
    assert code == 0 and "2 members, 4 curves and logs" in output, output
    assert (out / "curves_member1.png").read_bytes() == b"curves of seed1"
    assert (out / "train_member0.log").read_text() == "log of seed0\n"
    ensemble = load_learned_model(out, body)
    a, b = load_learned_model(first), load_learned_model(second)
    assert ensemble.version == "test-ensemble" and ensemble.latent_sizes == [25, 25]
    info = json.loads((out / "model.json").read_text())
    assert info["command"].startswith("usd-garment train combine")
    assert [member["source"] for member in info["members"]] == [str(first), str(second)]

    motion = make_motion("walk", 12, 60.0, seed=3, body=body)
    z = predict_latents(ensemble, motion)
    za, zb = predict_latents(a, motion), predict_latents(b, motion)
    assert z.shape == (12, 50) and torch.equal(z, torch.cat([za, zb], dim=1))
    with torch.no_grad():
        mean = (a.decode(za) + b.decode(zb)) / 2
        torch.testing.assert_close(ensemble.decode(z), mean)
        assert (a.decode(za) - b.decode(zb)).abs().max() > 1e-3  # the members differ

    code, output = _run(["train", "combine", out, first, "--out", tmp_path / "three"])
    assert code == 0 and "3 members" in output, output
    sources = [m.info["source"] for m in load_learned_model(tmp_path / "three").members]
    assert sources == [str(first), str(second), str(first)]
    logs = [(tmp_path / "three" / f"train_member{i}.log").read_text() for i in range(3)]
    assert logs == ["log of seed0\n", "log of seed1\n", "log of seed0\n"]

    layer = tmp_path / "walk.usda"
    write_body_layer(layer, motion, body)
    garment = tmp_path / "walk_tshirt.usdc"
    code, output = _run(["dress", layer, "-o", garment, "--model", out, "--lod", "low"])
    assert code == 0, output
    points, _, frames = read_garment_layer(garment)
    assert points.shape == (12, len(template.vertices), 3) and np.isfinite(points).all()
    stage = Usd.Stage.Open(str(garment))
    version = stage.GetPrimAtPath(frames.mesh).GetAttribute("garment:modelVersion")
    assert version.Get() == "test-ensemble"


def test_a_member_of_an_ensemble_is_written_as_a_model_of_its_own(tmp_path, body, template):
    first, second = _members(tmp_path, body, template)
    (second / "curves.png").write_bytes(b"curves of seed1")
    ensemble = tmp_path / "ensemble"
    assert _run(["train", "combine", first, second, "--out", ensemble])[0] == 0
    out = tmp_path / "member1"
    code, output = _run(["train", "member", ensemble, "--index", "1", "--out", out])
    assert code == 0 and "member 1" in output and "1 curves and logs" in output, output
    assert (out / "curves.png").read_bytes() == b"curves of seed1"
    alone, original = load_learned_model(out, body), load_learned_model(second)
    assert alone.version == "test-ensemble-member1" and len(alone.members) == 1
    assert alone.members[0].info["source"] == str(second)
    assert json.loads((out / "model.json").read_text())["command"].startswith(
        "usd-garment train member"
    )
    motion = make_motion("walk", 8, 30.0, seed=1, body=body)
    z = predict_latents(alone, motion)
    torch.testing.assert_close(z, predict_latents(original, motion))
    with torch.no_grad():
        torch.testing.assert_close(alone.decode(z), original.decode(z))

    code, output = _run(["train", "member", ensemble, "--index", "2", "--out", tmp_path / "x"])
    assert code == 1 and "no member 2: the model has 2 (0 to 1)" in output, output
    assert not (tmp_path / "x").exists()
    code, output = _run(["train", "member", ensemble, "--index", "0", "--out", ensemble])
    assert code == 2 and "is the model itself" in output, output


def _smoothed(
    tmp_path: Path, body: BodyModel, template: GarmentTemplate, kind: str, seconds: str
) -> tuple[list[Path], Path, dict[str, object]]:
    """Two members, and ``train combine --{kind}-smoothing seconds`` of them (checked: the
    setting and the command in ``model.json``; a negative value refused, nothing written)."""
    members = _members(tmp_path, body, template)
    option, out = f"--{kind}-smoothing", tmp_path / "smoothed"
    code, output = _run(["train", "combine", *members, "--out", out, option, seconds])
    assert code == 0, output
    info = json.loads((out / "model.json").read_text())
    assert info[f"{kind}_smoothing_s"] == float(seconds)
    assert f"{option} {seconds}" in info["command"]
    code, output = _run(["train", "combine", *members, "--out", tmp_path / "x", option, "-1"])
    assert code == 2 and "-1" in output and not (tmp_path / "x").exists(), output
    return members, out, info


def _both_smoothings(tmp_path: Path, body: BodyModel, template: GarmentTemplate) -> Path:
    """A model directory with both smoothings: :func:`_smoothed`'s latent one of 0.1 s and a
    posed one of 0.05 s."""
    _, out, _ = _smoothed(tmp_path, body, template, "latent", "0.1")
    both = tmp_path / "both"
    save_learned_model(both, replace(load_learned_model(out), posed_smoothing=0.05))
    return both


def _kept_and_checked(
    tmp_path: Path, out: Path, info: dict[str, object], kind: str, bad: float
) -> None:
    """The smoothing ``kind`` of the model ``out`` (``model.json``: ``info``): kept by ``train
    member`` (a member is benched as it runs), refused when ``bad``, 0 where ``model.json``
    has none (models written before the setting)."""
    key = f"{kind}_smoothing_s"
    assert _run(["train", "member", out, "--index", "1", "--out", tmp_path / "m1"])[0] == 0
    stored = getattr(load_learned_model(out), f"{kind}_smoothing")
    assert getattr(load_learned_model(tmp_path / "m1"), f"{kind}_smoothing") == stored > 0
    (out / "model.json").write_text(json.dumps({**info, key: bad}))
    with pytest.raises(ModelError, match=f"{key} must be a finite number"):
        load_learned_model(out)
    (out / "model.json").write_text(json.dumps({k: v for k, v in info.items() if k != key}))
    assert getattr(load_learned_model(out), f"{kind}_smoothing") == 0.0


def test_latent_smoothing_is_a_gaussian_over_the_codes_at_30_fps(tmp_path, body, template):
    _, out, info = _smoothed(tmp_path, body, template, "latent", "0.1")
    smoothed = load_learned_model(out, body)
    plain = replace(smoothed, latent_smoothing=0.0)
    assert smoothed.latent_smoothing == 0.1
    motion = make_motion("walk", 40, 30.0, seed=2, body=body)
    z, raw = predict_latents(smoothed, motion), predict_latents(plain, motion)
    # 0.1 s at 30 fps: σ = 3 frames, mirrored at the ends; ΣL columns smoothed one by one.
    expected = gaussian_filter1d(raw.numpy(), 3.0, axis=0, mode="mirror")
    np.testing.assert_allclose(z.numpy(), expected, atol=1e-6)
    assert (z.diff(n=2, dim=0).abs().mean() < 0.5 * raw.diff(n=2, dim=0).abs().mean()).item()
    _kept_and_checked(tmp_path, out, info, "latent", -0.5)


def test_latent_smoothing_stops_at_restarts_and_goes_on_across_a_root_jump(
    tmp_path, body, template
):
    """A walk cut at frame 20 where another motion starts (declared in ``cut_times``, a
    restart): the codes of each side are smoothed on their own, mirrored at the cut as at the
    ends, so that no frame takes the codes of the other side. The same walk whose root
    teleports 0.5 m at frame 20 (a cut, ``root_cuts``, but one motion going on, whose codes see
    no offset): smoothed across, as a walk without the jump."""
    _, out, _ = _smoothed(tmp_path, body, template, "latent", "0.1")
    smoothed = load_learned_model(out, body)
    plain = replace(smoothed, latent_smoothing=0.0)
    motion = make_motion("walk", 40, 30.0, seed=2, body=body)
    declared = replace(motion, cut_times=(float(motion.time_codes[20]),))
    assert motion_restarts(declared) == (20,)
    z, raw = predict_latents(smoothed, declared).numpy(), predict_latents(plain, declared).numpy()
    runs = [gaussian_filter1d(raw[a:b], 3.0, axis=0, mode="mirror") for a, b in ((0, 20), (20, 40))]
    np.testing.assert_allclose(z, np.concatenate(runs), atol=1e-6)
    across = gaussian_filter1d(raw, 3.0, axis=0, mode="mirror")
    assert np.abs(across - z)[17:23].max() > 10 * np.abs(across - z)[:10].max()
    trans = motion.trans.copy()
    trans[20:, 0] += 0.5
    jumped = replace(motion, trans=trans)
    assert root_cuts(jumped) == (20,) and motion_restarts(jumped) == ()
    z, raw = predict_latents(smoothed, jumped).numpy(), predict_latents(plain, jumped).numpy()
    np.testing.assert_allclose(z, gaussian_filter1d(raw, 3.0, axis=0, mode="mirror"), atol=1e-6)


def test_the_frames_before_a_cut_are_the_garment_of_the_clip_before_it(tmp_path, body, template):
    """A walk, then an arm swing 1 m away with no transition (a cut, at 120 fps between two of
    the model's frames), dressed by a model with both smoothings: the frames before the cut are
    the walk's dressed alone (its motion described, its codes smoothed and brought back to the
    input's frames, its posed garment smoothed, each on its own)."""
    both = _both_smoothings(tmp_path, body, template)
    walk = make_motion("walk", 22, 120.0, seed=2, body=body)
    swing = make_motion("arm_swing", 20, 120.0, seed=3, body=body)
    pose = np.concatenate([walk.pose, swing.pose])
    trans = np.concatenate([walk.trans, swing.trans + np.array([1.0, 0.0, 0.0])])
    joined = SmplMotion(walk.betas, pose, trans, 120.0, model=walk.model)
    assert root_cuts(joined) == (22,) and motion_restarts(joined) == (22,)
    method = SmoothedAlone(both, exact_fields=True)
    before = method.predict(joined, body, template)[:22]
    np.testing.assert_allclose(before, method.predict(walk, body, template), atol=1e-5)


def test_the_frames_from_a_cut_on_are_the_garment_of_the_clip_after_it(tmp_path, body, template):
    """A walk, then an arm swing 1 m away (a cut at frame 20, 30 fps), dressed by a model with
    both smoothings: from the cut on, the frames are the swing's dressed alone, its GRU started
    from rest there as at a clip's first frame; the state the walk left is not carried over. A
    jump of the root alone (the walk moved 1 m from frame 10) is a cut but not a restart: the
    state carries across it."""
    both = _both_smoothings(tmp_path, body, template)
    walk = make_motion("walk", 20, 30.0, seed=2, body=body)
    swing = make_motion("arm_swing", 20, 30.0, seed=3, body=body)
    moved = replace(swing, betas=walk.betas, trans=swing.trans + np.array([1.0, 0.0, 0.0]))
    pose = np.concatenate([walk.pose, moved.pose])
    joined = replace(walk, pose=pose, trans=np.concatenate([walk.trans, moved.trans]))
    assert root_cuts(joined) == (20,) and motion_restarts(joined) == (20,)
    model = load_learned_model(both, body)
    torch.testing.assert_close(predict_latents(model, joined)[20:], predict_latents(model, moved))
    method = SmoothedAlone(both, exact_fields=True)
    after = method.predict(joined, body, template)[20:]
    np.testing.assert_allclose(after, method.predict(moved, body, template), atol=1e-5)
    trans = walk.trans.copy()
    trans[10:, 0] += 1.0  # a jump of the root alone: the same walk going on, moved
    jumped = replace(walk, trans=trans)
    assert root_cuts(jumped) == (10,) and motion_restarts(jumped) == ()
    plain = replace(model, latent_smoothing=0.0)  # the GRU alone
    carried = predict_latents(plain, jumped)
    torch.testing.assert_close(carried, predict_latents(plain, jumped, restarts=()))
    anew = predict_latents(plain, jumped, restarts=(10,))
    torch.testing.assert_close(carried[:10], anew[:10])
    assert (carried[10:] - anew[10:]).abs().max() > 1e-3


def test_a_jump_of_the_root_alone_is_taken_out(tmp_path, body, template):
    """A walk moved 0.5 m and turned 90° about the up axis from frame 20 on (a jump of the root
    alone: a cut, no restart), dressed by a model with both smoothings, is the walk dressed
    before the jump and the walk moved whole dressed from it on: the networks see the motion
    with the jump taken out (``without_jumps``) and the posed smoothing goes on across it with
    the jump taken out. Within 1 mm, what the root's change of step there leaves (the map
    assumes the steps on each side of the jump meet midway): 0.11 mm at most here, where stop
    85's code, which stopped the descriptor and the posed smoothing there, is 29 mm off."""
    both = _both_smoothings(tmp_path, body, template)
    walk = make_motion("walk", 40, 30.0, seed=2, body=body)
    turn = Rotation.from_rotvec([0.0, np.pi / 2, 0.0])
    pose = walk.pose.copy()
    pose[:, 0] = (turn * Rotation.from_rotvec(walk.pose[:, 0])).as_rotvec()
    moved = replace(walk, pose=pose, trans=turn.apply(walk.trans) + np.array([0.5, 0.0, 0.0]))
    jumped = replace(walk, pose=walk.pose.copy(), trans=walk.trans.copy())
    jumped.pose[20:], jumped.trans[20:] = moved.pose[20:], moved.trans[20:]
    assert root_cuts(jumped) == (20,) and motion_restarts(jumped) == ()
    method = SmoothedAlone(both, exact_fields=True)
    got = method.predict(jumped, body, template)
    before = np.abs(got[:20] - method.predict(walk, body, template)[:20]).max()
    after = np.abs(got[20:] - method.predict(moved, body, template)[20:]).max()
    assert max(before, after) < 1e-3, (before, after)
    # ``dress`` reports the jump as one, not as a place where the motion starts anew.
    layer = tmp_path / "jumped.usda"
    write_body_layer(layer, jumped, body)
    args = ["dress", layer, "--method", "learned", "--model", both, "--lod", "low"]
    code, output = _run([*args, "-o", tmp_path / "a.usdc", "--json"])
    assert code == 0, output
    assert json.loads(output)["cuts"] == json.loads(output)["root_jumps"] == [20.0]
    code, output = _run([*args, "-o", tmp_path / "b.usdc"])
    assert "the root alone jumps at time codes 20 (one motion going on, moved)" in output
    assert "starts anew" not in output


def test_a_splice_of_the_joints_alone_is_found_or_declared(tmp_path, body, template):
    """A walk whose joints take an arm swing's from frame 22 on while its root walks on (an
    edit's splice: no root jump, so ``root_cuts`` finds none), at 120 fps, is found by
    ``joint_cuts``: the frames before it are the walk's dressed alone, as at a declared cut. A
    splice too small to be found (the left shoulder turned 0.3 rad more from frame 22) is cut
    where it is declared in ``smpl:cuts`` (or ``dress --cut``); undeclared, both smoothings
    reach across it. ``dress`` reports the cuts and honours the layer's declaration and
    ``--cut`` alike."""
    both = _both_smoothings(tmp_path, body, template)
    walk = make_motion("walk", 42, 120.0, seed=2, body=body)
    swing = make_motion("arm_swing", 20, 120.0, seed=3, body=body)
    pose = walk.pose.copy()
    pose[22:, 1:] = swing.pose[:, 1:]
    spliced = replace(walk, pose=pose)
    assert root_cuts(spliced) == () and motion_cuts(spliced) == (22,)
    method = SmoothedAlone(both, exact_fields=True)
    alone = method.predict(replace(walk, pose=pose[:22], trans=walk.trans[:22]), body, template)
    np.testing.assert_allclose(method.predict(spliced, body, template)[:22], alone, atol=1e-5)
    small = walk.pose.copy()
    turn = Rotation.from_rotvec([0.0, 0.0, 0.3]) * Rotation.from_rotvec(small[22:, 16])
    small[22:, 16] = turn.as_rotvec()
    nudged = replace(walk, pose=small)
    declared = replace(nudged, cut_times=(22.0,))
    assert motion_cuts(nudged) == () and motion_cuts(declared) == (22,)
    alone = method.predict(replace(walk, pose=small[:22], trans=walk.trans[:22]), body, template)
    np.testing.assert_allclose(method.predict(declared, body, template)[:22], alone, atol=1e-5)
    across = method.predict(nudged, body, template)[:22]
    assert np.abs(across - alone)[-3:].max() > 1e-3
    marked, plain, found = (tmp_path / f"{name}.usda" for name in ("marked", "plain", "found"))
    write_body_layer(marked, declared, body)
    write_body_layer(plain, nudged, body)
    write_body_layer(found, spliced, body)
    layers = []
    dress = ["--method", "learned", "--model", both, "--lod", "low", "--json"]
    runs = ((marked, [], [22.0]), (plain, ["--cut", "22"], [22.0]), (plain, [], []),
            (found, [], [22.0]))  # fmt: skip
    for source, extra, cuts in runs:
        layers.append(tmp_path / f"out{len(layers)}.usdc")
        code, output = _run(["dress", source, "-o", layers[-1], *dress, *extra])
        assert code == 0, output
        assert json.loads(output)["cuts"] == cuts and json.loads(output)["root_jumps"] == []
    code, output = _run(["dress", marked, "-o", tmp_path / "text.usdc", *dress[:-1]])
    assert "starts anew at time codes 22\n" in output and "jumps" not in output
    first, second, third = (read_garment_layer(p)[0] for p in layers[:3])
    np.testing.assert_array_equal(first, second)
    assert np.abs(first - third).max() > 1e-4


def test_posed_smoothing_is_a_gaussian_over_the_posed_frames(tmp_path, body, template):
    """``train combine --posed-smoothing S``: the posed garment is smoothed by a Gaussian of S
    seconds at the input's frame rate, the nearest frame repeated at the ends, and a motion
    streamed in chunks is smoothed as it is whole (each chunk posed with the frames around it
    that the Gaussian reaches); ``train member`` keeps it; a negative one is refused. The
    networks alone (``learned``) are not smoothed: nothing would keep the smoothed vertices out
    of their own body parts (``LearnedMethod.smooths``); the smoothing alone is checked here
    through a method that smooths with no push at all."""
    (first, second), out, info = _smoothed(tmp_path, body, template, "posed", "0.05")
    assert info["latent_smoothing_s"] == 0.0
    plain_dir = tmp_path / "plain"
    assert _run(["train", "combine", first, second, "--out", plain_dir])[0] == 0
    motion = make_motion("walk", 40, 30.0, seed=2, body=body)
    smoothed = SmoothedAlone(out, exact_fields=True).predict_stream(motion, body, template, 7)
    chunks = list(smoothed)
    assert [len(c) for c in chunks] == [7] * 5 + [5]
    whole = LearnedMethod(plain_dir, exact_fields=True).predict_stream(motion, body, template, 40)
    raw = np.concatenate(list(whole))
    alone = LearnedMethod(out, exact_fields=True).predict_stream(motion, body, template, 40)
    assert np.array_equal(np.concatenate(list(alone)), raw)  # learned: not smoothed
    # 0.05 s at 30 fps: σ = 1.5 frames, reaching int(4 σ + 0.5) = 6 frames around each chunk.
    expected = gaussian_filter1d(raw, 1.5, axis=0, mode="nearest")
    np.testing.assert_allclose(np.concatenate(chunks), expected, atol=2e-5)
    assert np.abs(np.diff(expected, n=2, axis=0)).mean() < np.abs(np.diff(raw, n=2, axis=0)).mean()
    _kept_and_checked(tmp_path, out, info, "posed", float("nan"))


def test_saved_model_files_get_the_usual_permissions(tmp_path, body, template):
    """safetensors makes its file 0600; a saved model is readable as any output (umask)."""
    (path,) = _members(tmp_path, body, template)[:1]
    umask = os.umask(0)
    os.umask(umask)
    for name in ("weights.safetensors", "model.json"):
        assert stat.S_IMODE((path / name).stat().st_mode) == 0o666 & ~umask, name


def test_combine_refuses_mismatched_models(tmp_path, body, template, synthetic_body):
    first, second = _members(tmp_path, body, template)
    medium = tmp_path / "medium"
    save_learned_model(medium, untrained_model(body, load_template("tshirt", "medium")))
    other_body = tmp_path / "other_body"
    save_learned_model(other_body, untrained_model(synthetic_body, template))
    out = tmp_path / "out"
    for models, message in (
        ([first], "at least two"),
        ([first, medium], "not the low tshirt"),
        ([first, other_body], "trained for the body"),
        ([first, tmp_path], "not a model directory"),
    ):
        code, output = _run(["train", "combine", *models, "--out", out])
        assert code == 1 and message in output, output
    code, output = _run(["train", "combine", first, second, "--out", second])
    assert code == 2 and "one of the models" in output
    assert not out.exists()
    assert load_learned_model(second).version == "test"


def test_a_model_of_the_first_layout_still_loads(tmp_path, body, template):
    """Format 1: one member, its architectures under "architecture", its weights unprefixed."""
    (path,) = _members(tmp_path, body, template)[:1]
    config = json.loads((path / "model.json").read_text())
    (member,) = config.pop("members")
    config |= {"format": 1, "architecture": member["architecture"]}
    (path / "model.json").write_text(json.dumps(config))
    tensors = load_file(str(path / "weights.safetensors"))
    save_file(
        {k.removeprefix("0."): v for k, v in tensors.items()}, str(path / "weights.safetensors")
    )
    old = load_learned_model(path, body)
    new = untrained_model(body, template, 0)
    z = torch.randn(4, 25, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():  # the weights were stored in float16
        torch.testing.assert_close(old.decode(z), new.decode(z), atol=2e-4, rtol=0)
    assert len(old.members) == 1 and old.members[0].info == {}


def test_an_ensemble_stored_in_int8_is_smaller_and_decodes_as_its_members(tmp_path, body, template):
    first, second = _members(tmp_path, body, template)
    half, quarter = tmp_path / "float16", tmp_path / "int8"
    assert _run(["train", "combine", first, second, "--out", half])[0] == 0
    code, output = _run(["train", "combine", first, second, "--out", quarter, "--weights", "int8"])
    assert code == 0, output
    info = json.loads((quarter / "model.json").read_text())
    assert (info["format"], info["weights"]) == (3, "int8") and "--weights int8" in info["command"]
    assert json.loads((half / "model.json").read_text())["format"] == 2
    learned = sum(p.numel() for m in load_learned_model(half).members for p in m.vae.parameters())
    saved = (half / "weights.safetensors").stat().st_size
    assert (quarter / "weights.safetensors").stat().st_size < saved - learned // 2

    a, b = load_learned_model(half, body), load_learned_model(quarter, body)
    z = torch.randn(6, 50, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():  # the canonical garment moves by far less than a millimetre
        assert 0 < (a.decode(z) - b.decode(z)).abs().max() < 3e-4
    motion = make_motion("walk", 8, 30.0, seed=2, body=body)
    torch.testing.assert_close(
        predict_latents(b, motion), predict_latents(a, motion), atol=0.05, rtol=0
    )

    one = tmp_path / "member0"
    assert _run(["train", "member", quarter, "--index", "0", "--out", one])[0] == 0
    assert json.loads((one / "model.json").read_text())["format"] == 2  # float16 by default

    tensors = load_file(str(quarter / "weights.safetensors"))
    name = next(k for k in tensors if k.endswith("#scale"))
    tensors[name] = tensors[name][:-1]
    save_file(tensors, str(quarter / "weights.safetensors"))
    with pytest.raises(ModelError, match="model files do not match"):
        load_learned_model(quarter)


def test_capture_members_script_trains_two_members_and_joins_five_in_int8(tmp_path):
    """``examples/train/capture_members.sh`` (the T-shirt's version 10): one base, each seed's
    three regressor steps from it, the kept model's members, the five joined as int8."""
    from tests.script_calls import script_calls

    kept = tmp_path / "v9"
    kept.mkdir()
    (kept / "model.json").write_text(json.dumps({"members": [{}, {}, {}]}))
    calls = script_calls("capture_members.sh", str(kept), "out", "d", "c", tmp_path=tmp_path)
    trains = [c for c in calls if c[1] in ("all", "regressor")]
    assert trains[0][:4] == ["train", "all", "--data", "d/canonical_tshirt_v4c.npz"]
    regressors = trains[1:]
    assert len(regressors) == 6
    steps = [(seed, step) for seed in (0, 1) for step in ("J0", "J1", "J")]
    for call, (seed, step) in zip(regressors, steps, strict=True):
        value = dict(zip(call[2::2], call[3::2], strict=False))
        assert value["--data"] == "c/canonical_tshirt_v4c.npz" and value["--seed"] == str(seed)
        assert value["--out"] == f"scratch/runs_cap/cap_{step}_s{seed}"
        fine_tuned = step != "J0"
        assert ("--planes" in value) == fine_tuned and ("--init-from" in value) == fine_tuned
    assert [c[2] for c in calls if c[1] == "member"] == [str(kept)] * 3
    (combine,) = [c for c in calls if c[1] == "combine"]
    assert combine[2:7] == [f"scratch/runs_cap/kept_m{i}" for i in range(3)] + [
        "scratch/runs_cap/cap_J_s0", "scratch/runs_cap/cap_J_s1"]  # fmt: skip
    assert combine[combine.index("--weights") + 1] == "int8"
    assert combine[combine.index("--out") + 1] == "out"


def test_capture_members_script_takes_a_base_trained_elsewhere(tmp_path):
    """``BASE=RUN capture_members.sh``: no base trained; each seed's first regressor step starts
    from a copy of RUN (table1.sh passes recipe.sh's member 0's first step, the same command);
    a BASE that holds no trained model is refused before any training."""
    from tests.script_calls import script_calls

    kept = tmp_path / "v9"
    kept.mkdir()
    (kept / "model.json").write_text(json.dumps({"members": [{}, {}, {}]}))
    base = tmp_path / "T30_m0"
    base.mkdir()
    (base / "model.json").write_text("{}")
    (base / "vae.marker").write_text("member 0's VAE")
    calls = script_calls("capture_members.sh", str(kept), "out", "d", "c", tmp_path=tmp_path,
                         env={"BASE": str(base)})  # fmt: skip
    assert not [c for c in calls if c[:2] == ["train", "all"]]
    assert len([c for c in calls if c[:2] == ["train", "regressor"]]) == 6
    for seed in (0, 1):
        copied = tmp_path / "work" / "scratch" / "runs_cap" / f"cap_J0_s{seed}" / "vae.marker"
        assert copied.read_text() == "member 0's VAE"
    (base / "model.json").unlink()
    (tmp_path / "again").mkdir()
    with pytest.raises(subprocess.CalledProcessError):
        script_calls("capture_members.sh", str(kept), "out", "d", "c",
                     tmp_path=tmp_path / "again", env={"BASE": str(base)})  # fmt: skip
    assert not (tmp_path / "again" / "calls.jsonl").exists()  # nothing ran
