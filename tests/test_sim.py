"""Tests of the training-data cloth simulator (``usd_garment.sim``): material mapping, panel
layout, frame checks (winding-number inside test, forced contact), short Newton runs of a cloth
tube on a moving capsule (bad frames kept, strict, long bad runs), and the lead-in of the
simulation method for strong body shapes."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
import trimesh

from usd_garment.eval.body_distance import BodySurface
from usd_garment.sim.checks import (
    CheckLimits,
    FrameCheck,
    check_frame,
    frame_body_distance,
    measure_frame,
    unique_edges,
)
from usd_garment.sim.cloth import (
    RELEASE_MODES,
    ContactRelease,
    ContactSettings,
    GarmentSimulator,
    SimResult,
    panel_layout,
    simulate_sequence,
)
from usd_garment.sim.material import ClothMaterial

pytest.importorskip("newton")


def tube(radius: float, length: float, around: int, along: int) -> tuple[np.ndarray, np.ndarray]:
    """An open cylinder along X, faces counter-clockwise seen from outside."""
    theta = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    x = np.linspace(-length / 2, length / 2, along)
    xx, tt = np.meshgrid(x, theta, indexing="ij")
    vertices = np.stack([xx, radius * np.cos(tt), radius * np.sin(tt)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(along - 1), np.arange(around), indexing="ij")
    a = i * around + j
    b = i * around + (j + 1) % around
    faces = np.concatenate(
        [np.stack([a, b, a + around], -1), np.stack([b, b + around, a + around], -1)]
    ).reshape(-1, 3)
    return vertices, faces


def capsule() -> trimesh.Trimesh:
    """A horizontal capsule (an arm), 0.62 m long along X, radius 6 cm."""
    body = trimesh.creation.capsule(height=0.5, radius=0.06, count=[16, 16])
    body.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    return body


def swing(body: np.ndarray, frames: int, fps: float, speed: float) -> np.ndarray:
    """``(T, V, 3)`` body frames: a yaw swing of ±0.5·speed rad plus a translation."""
    t = np.arange(1, frames + 1)[:, None] / fps
    yaw = 0.5 * speed * np.sin(2 * np.pi * 0.7 * t)
    x = body[None, :, 0] * np.cos(yaw) + body[None, :, 2] * np.sin(yaw)
    z = -body[None, :, 0] * np.sin(yaw) + body[None, :, 2] * np.cos(yaw)
    x = x + 0.1 * speed * np.sin(2 * np.pi * t)
    y = body[None, :, 1] + 0.05 * speed * np.sin(2 * np.pi * 1.3 * t)
    return np.stack([x, y, z], axis=-1)


def test_material_mapping_and_json(tmp_path) -> None:
    cotton = ClothMaterial()
    h, mu, lam = 4.7e-4, 2.36e4, 4.44e4
    assert cotton.shear_stiffness == pytest.approx(h * mu)
    assert cotton.stretch_stiffness == pytest.approx(h * 4 * mu * (lam + mu) / (lam + 2 * mu))
    assert cotton.solver_bending_stiffness == pytest.approx(3.96e-5 / 12)
    path = tmp_path / "silk.json"
    path.write_text(json.dumps({"area_density": 0.1, "bending": 1e-6}))
    silk = ClothMaterial.load(path)
    assert silk.area_density == 0.1 and silk.lame_mu == cotton.lame_mu
    assert ClothMaterial.from_dict(silk.to_dict()) == silk
    path.write_text(json.dumps({"density": 0.1}))
    with pytest.raises(ValueError, match="unknown material key"):
        ClothMaterial.load(path)
    with pytest.raises(ValueError, match="finite"):
        ClothMaterial(bending=-1.0)


def test_bending_mapping_matches_a_bent_hinge() -> None:
    """Style3D's quadratic bending energy of a hinge bent by θ equals SNUG's k_b θ²|e|²/(8A)."""
    rest = np.array([[0.3, 0.5, 0.0], [-0.2, -0.7, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])

    def cot(apex: np.ndarray, p: np.ndarray, q: np.ndarray) -> float:
        u, v = p - apex, q - apex
        return float(u @ v / np.linalg.norm(np.cross(u, v)))

    o0, o1, v0, v1 = rest
    c = [cot(v0, v1, o0), cot(v0, v1, o1), cot(v1, v0, o0), cot(v1, v0, o1)]
    w = np.array([-c[0] - c[2], -c[1] - c[3], c[2] + c[3], c[0] + c[1]])
    area = 0.5 * (
        np.linalg.norm(np.cross(v1 - v0, o0 - v0)) + np.linalg.norm(np.cross(v1 - v0, o1 - v0))
    )
    theta = 0.05
    bent = rest.copy()
    bent[1] = [bent[1, 0], bent[1, 1] * np.cos(theta), bent[1, 1] * np.sin(theta)]
    k = ClothMaterial().solver_bending_stiffness
    style3d = 0.5 * k * 3.0 / area * np.sum((w @ bent) ** 2)
    snug = 3.96e-5 * theta**2 * 1.0 / (8 * area)
    assert style3d == pytest.approx(snug, rel=1e-3)


def test_panel_layout_keeps_rest_geometry() -> None:
    vertices, faces = tube(0.1, 0.3, 12, 5)
    panels = panel_layout(vertices, faces)
    tri = vertices[faces]
    for i, j in ((0, 1), (1, 2), (2, 0)):
        np.testing.assert_allclose(
            np.linalg.norm(panels[:, i] - panels[:, j], axis=1),
            np.linalg.norm(tri[:, i] - tri[:, j], axis=1),
            atol=1e-12,
        )
    e1, e2 = panels[:, 1] - panels[:, 0], panels[:, 2] - panels[:, 0]
    assert (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0).all()


def test_checks_flag_inside_far_stretch_and_nan() -> None:
    body = capsule()
    vertices, faces = tube(0.07, 0.3, 12, 5)
    edges = unique_edges(faces)
    rest = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    limits = CheckLimits()

    def check(points: np.ndarray):
        sdf = -trimesh.proximity.signed_distance(body, points)  # trimesh: positive inside
        return check_frame(points, sdf, rest, edges, limits)

    good = check(vertices)
    assert good.failures(limits) == [] and good.inside_share == 0.0
    assert 0.0099 < good.max_distance < 0.012  # the capsule is a 16-gon
    inside = check(vertices * [1, 0.5, 0.5])
    assert inside.inside_share == 1.0 and "inside" in " ".join(inside.failures(limits))
    far = check(vertices + np.array([0.0, 1.0, 0.0]))
    assert far.inside_share == 0.0 and "from the body" in " ".join(far.failures(limits))
    stretched = check(vertices * [1.5, 1, 1])
    assert stretched.stretch_p99 == pytest.approx(1.5) and stretched.failures(limits)
    broken = vertices.copy()
    broken[3] = np.nan
    assert check_frame(broken, np.zeros(len(broken)), rest, edges, limits).nan_count == 1


def test_simulator_body_distance_matches_reference() -> None:
    """The simulator's query (the shared winding-number one, closest point among the nearest
    triangles by centroid: exact on evenly sized triangles) agrees with trimesh's exact signed
    distance on a closed sphere."""
    body = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    vertices, faces = tube(0.075, 0.4, 12, 7)
    sim = GarmentSimulator(vertices, faces, body.faces, body.vertices)
    points = np.random.default_rng(0).uniform(-0.2, 0.2, vertices.shape)
    sim.state_0.particle_q.assign(points.astype(np.float32))
    reference = -trimesh.proximity.signed_distance(body, points)
    np.testing.assert_allclose(sim.body_distance(), reference, atol=1e-5)


def test_projection_keeps_no_velocity_against_the_move() -> None:
    """``project`` moves the vertices and removes the velocity component against each move (an
    inelastic contact), keeping the rest of it; vertices that do not move keep theirs."""
    body = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    vertices, faces = tube(0.075, 0.4, 8, 4)
    sim = GarmentSimulator(vertices, faces, body.faces, body.vertices)
    velocity = np.tile([[-1.0, 0.5, 0.0]], (len(vertices), 1))  # into -x, along +y
    sim.state_0.particle_qd.assign(velocity.astype(np.float32))
    moved = vertices.copy()
    moved[:4, 0] += 0.003  # pushed out along +x
    moved[4:8, 0] -= 0.003  # pushed along -x: the velocity is not against the move
    sim.project(moved)
    np.testing.assert_allclose(sim.points, moved, atol=1e-6)
    after = sim.state_0.particle_qd.numpy()
    np.testing.assert_allclose(after[:4], [[0.0, 0.5, 0.0]] * 4, atol=1e-6)
    np.testing.assert_allclose(after[4:], velocity[4:], atol=1e-6)


def test_projection_moves_cloth_out_of_the_body() -> None:
    """A sleeve at rest 3 cm deep in a still arm: the end-of-frame projection moves it out
    (no vertex left inside after the first frame) and the per-frame quality says how many it
    moved; without the projection none is counted."""
    body = capsule()
    vertices, faces = tube(0.075, 0.4, 12, 7)
    sleeve = vertices * np.array([1.0, 0.4, 0.4])  # at rest 3 cm inside the 6 cm arm
    frames = np.repeat(np.asarray(body.vertices)[None], 2, axis=0)
    results = {
        project: simulate_sequence(
            sleeve, faces, body.faces, frames, settle_frames=0,
            contact=ContactSettings(project=project), max_substeps=4,
        )
        for project in (True, False)
    }  # fmt: skip
    on, off = results[True], results[False]
    assert on.ok and off.ok
    assert on.projected[0] > 0.9 and on.checks[0].inside_share == 0.0
    assert off.projected == [0.0, 0.0]


def test_limits_per_garment() -> None:
    """A dress's hem swings free of the legs: its fell-off distance is beyond the T-shirt's."""
    assert CheckLimits.for_garment("tshirt") == CheckLimits()
    assert CheckLimits.for_garment("dress").max_distance > 2 * CheckLimits().max_distance
    assert CheckLimits.for_garment("dress").far_distance > 2 * CheckLimits().max_distance


def test_far_frame_is_retried_but_not_fatal() -> None:
    """A vertex beyond the 10 cm target but within the 15 cm fell-off distance fails the frame
    (it is simulated again with more substeps, flagged bad if it stays) without ending the
    sequence; beyond 15 cm it is fatal."""
    limits = CheckLimits()
    check = FrameCheck(
        nan_count=0, inside_share=0.0, inside_forced_share=0.0, inside_elsewhere_share=0.0,
        penetrating_share=0.0, max_distance=0.12, stretch_p99=1.1, stretch_max=1.2,
    )  # fmt: skip
    assert check.failures(limits) == ["a vertex 0.120 m from the body"]
    assert check.fatal(limits) == []
    assert check.failures(CheckLimits.for_garment("dress")) == []
    fell = replace(check, max_distance=0.16)
    assert fell.fatal(limits) == ["a vertex 0.160 m from the body (fell off)"]


def test_a_snagged_edge_fails_the_frame_though_the_p99_passes() -> None:
    """One edge stretched past ``max_edge_stretch`` (a hem vertex caught on a thigh) fails the
    frame, so it is simulated again with more substeps, while the p99 is within its limit; it
    is not fatal."""
    limits = CheckLimits()
    check = FrameCheck(
        nan_count=0, inside_share=0.0, inside_forced_share=0.0, inside_elsewhere_share=0.0,
        penetrating_share=0.0, max_distance=0.05, stretch_p99=1.2, stretch_max=3.0,
    )  # fmt: skip
    assert check.failures(limits) == ["an edge stretched 3.00x"] and check.fatal(limits) == []
    assert replace(check, stretch_max=limits.max_edge_stretch).failures(limits) == []


def test_a_failure_message_names_the_forced_share() -> None:
    """A frame that fails on stretch while cloth lies inside the body where the pose forces it
    (a limb through the trunk) says so in the clause added to its failure message; without
    forced vertices (or with a NaN share, a NaN frame) the clause is empty."""
    check = FrameCheck(
        nan_count=0, inside_share=0.033, inside_forced_share=0.033, inside_elsewhere_share=0.0,
        penetrating_share=0.0, max_distance=0.05, stretch_p99=1.367, stretch_max=6.62,
    )  # fmt: skip
    assert check.failures(CheckLimits()) == ["edge stretch p99 1.367", "an edge stretched 6.62x"]
    assert check.forced_note() == (
        "; 3.30% of the vertices inside the body where the pose presses a limb into it"
    )
    assert replace(check, inside_forced_share=0.0).forced_note() == ""
    assert replace(check, inside_forced_share=float("nan")).forced_note() == ""


def test_forced_contact_is_not_a_failure() -> None:
    """Cloth on an arm pressed into the trunk lies inside the body, forced by the pose: the
    frame passes; the same share inside elsewhere fails it."""
    trunk = trimesh.creation.capsule(height=0.4, radius=0.12, count=[24, 24])  # along Z
    arm = capsule()  # along X, radius 6 cm
    arm.apply_translation([0.25, 0.0, 0.0])  # its cylinder from the trunk's axis outwards
    body = trimesh.util.concatenate([trunk, arm])
    surface = BodySurface(body.faces, len(body.vertices))
    sleeve, faces = tube(0.062, 0.4, 16, 9)  # 2 mm off the arm; rings 5 cm apart
    sleeve = sleeve + np.array([0.24, 0.0, 0.0])  # rings at x = 4 and 9 cm inside the trunk
    edges = unique_edges(faces)
    rest = np.linalg.norm(sleeve[edges[:, 0]] - sleeve[edges[:, 1]], axis=1)
    limits = CheckLimits()
    check = measure_frame(sleeve, body.vertices, surface, rest, edges, limits)
    assert check.inside_share > 0.05  # the first ring(s) of the sleeve are inside the trunk
    assert check.inside_forced_share == pytest.approx(check.inside_share)
    assert check.inside_elsewhere_share == 0.0 and check.failures(limits) == []
    distance, forced = frame_body_distance(sleeve, body.vertices, surface)
    assert (forced == (distance < 0)).all()
    unforced = check_frame(sleeve, distance, rest, edges, limits)  # no forced flags
    assert unforced.inside_elsewhere_share == check.inside_share
    assert "inside the body" in " ".join(unforced.failures(limits))


def run_tube(frames: int, speed: float, around: int, along: int, **kwargs: Any) -> SimResult:
    """A tube of ``around`` × ``along`` vertices on the capsule swinging at ``speed``."""
    body = capsule()
    vertices, faces = tube(0.075, 0.4, around, along)
    motion = swing(np.asarray(body.vertices), frames, 30.0, speed)
    result = simulate_sequence(
        vertices, faces, body.faces, motion, body_rest=body.vertices, **kwargs
    )
    return result


def assert_good(result: SimResult, frames: int, max_stretch: float = 1.15) -> None:
    assert result.ok, result.message
    assert result.points.shape[0] == frames and np.isfinite(result.points).all()
    assert len(result.checks) == frames
    assert max(c.penetrating_share for c in result.checks) == 0.0
    assert max(c.max_distance for c in result.checks) < 0.10
    assert max(c.stretch_p99 for c in result.checks) <= max_stretch


def test_tube_on_moving_capsule() -> None:
    """~300-vertex tube, 12 frames; the first run compiles Warp kernels (~30 s, then cached)."""
    result = run_tube(frames=12, speed=1.0, around=24, along=13, lead_in=2, settle_frames=2)
    assert_good(result, 12)
    assert result.points.shape[1] == 24 * 13


def test_teleporting_body_fails_instead_of_returning_garbage() -> None:
    body = capsule()
    vertices, faces = tube(0.075, 0.4, 12, 7)
    motion = np.stack([body.vertices, body.vertices + np.array([0.0, 0.0, 1.0])])
    result = simulate_sequence(
        vertices, faces, body.faces, motion, lead_in=0, settle_frames=1, max_substeps=8
    )
    assert not result.ok and "motion frame 1" in result.message and "fell off" in result.message
    assert result.points.shape[0] == 1 and result.substeps[-1] == 8 and result.bad == [0, 1]


def test_bad_frames_are_kept_unless_strict() -> None:
    """With a stretch limit no frame meets, frames are kept and flagged; ``strict`` stops at the
    first; more than ``max_bad_run`` in a row fail with a clear message."""
    tight = CheckLimits(max_stretch=1.0)
    kwargs: dict[str, Any] = dict(lead_in=1, settle_frames=1, max_substeps=4, limits=tight)
    kept = run_tube(frames=3, speed=1.0, around=12, along=7, max_bad_run=100, **kwargs)
    assert kept.ok and kept.points.shape[0] == 3 and np.isfinite(kept.points).all()
    assert kept.bad == [True] * 3 and kept.lead_in_bad == [True] * 2 and kept.bad_frames == 5
    strict = run_tube(frames=3, speed=1.0, around=12, along=7, strict=True, **kwargs)
    assert not strict.ok and strict.message.startswith("lead-in frame 0: edge stretch p99")
    assert strict.points.shape[0] == 0
    run = run_tube(frames=3, speed=1.0, around=12, along=7, max_bad_run=3, **kwargs)
    assert not run.ok and run.points.shape[0] == 1
    assert run.message.startswith("motion frame 1: 4 bad frames in a row, the last with edge")


def test_released_contacts_are_dropped() -> None:
    """While ``releasing`` is set, ``step`` drops the body contacts of the released particles
    against the released skin (the body point's nearest vertex) and keeps every other."""
    body = capsule()
    sleeve, faces = tube(0.064, 0.4, 16, 9)  # 4 mm off the arm: every vertex in contact
    everywhere = np.ones(len(body.vertices), bool)

    def contacts(release: ContactRelease, releasing: bool) -> tuple[np.ndarray, np.ndarray, int]:
        sim = GarmentSimulator(sleeve, faces, body.faces, body.vertices, substeps=1,
                               release=release)  # fmt: skip
        sim.releasing = releasing
        sim.step(body.vertices)
        count = int(sim.contacts.soft_contact_count.numpy()[0])
        particle = sim.contacts.soft_contact_particle.numpy()[:count]
        return particle, sim.contacts.soft_contact_body_pos.numpy()[:count], sim.released_contacts

    right = sleeve[:, 0] > 0
    kept, _, none = contacts(ContactRelease(right, everywhere), False)
    assert none == 0 and right[kept].any() and (~right[kept]).any()
    released, _, dropped = contacts(ContactRelease(right, everywhere), True)
    assert not right[released].any() and dropped == right[kept].sum()
    np.testing.assert_array_equal(np.sort(released), np.sort(kept[~right[kept]]))
    left_skin = np.asarray(body.vertices)[:, 0] < 0
    particle, at, _ = contacts(ContactRelease(np.ones(len(sleeve), bool), left_skin), True)
    assert (at[:, 0] > -0.01).all() and (sleeve[particle, 0] > -0.02).all()
    assert set(np.flatnonzero(sleeve[:, 0] > 0.02)) <= set(particle)
    with pytest.raises(ValueError, match="release masks"):
        GarmentSimulator(sleeve, faces, body.faces, body.vertices,
                         release=ContactRelease(right[:-1], everywhere))  # fmt: skip
    with pytest.raises(ValueError, match="release must be one of"):
        ContactSettings(release="sometimes")


def test_a_frame_failing_with_the_most_substeps_gets_one_released_try() -> None:
    """``release="retry"``: a frame that fails its checks with the most substeps is simulated
    once more with the release contacts dropped, and that try is kept; frames that pass are
    simulated exactly as with ``"never"``; ``"always"`` releases every try."""
    release = ContactRelease(np.ones(12 * 7, bool), np.ones(len(capsule().vertices), bool))
    tight: dict[str, Any] = dict(lead_in=1, settle_frames=1, max_substeps=4, max_bad_run=100,
                                 limits=CheckLimits(max_stretch=1.0), release=release)  # fmt: skip
    runs = {
        mode: run_tube(frames=2, speed=1.0, around=12, along=7, contact=ContactSettings(
            release=mode), **tight)
        for mode in RELEASE_MODES
    }  # fmt: skip
    assert runs["never"].released == [False] * 2 and runs["always"].released == [True] * 2
    assert runs["retry"].released == [True] * 2 and runs["retry"].substeps == [4] * 2
    # Released from the whole arm the tube falls: the kept try is the released one.
    np.testing.assert_array_equal(runs["retry"].points, runs["always"].points)
    assert not np.allclose(runs["retry"].points, runs["never"].points, atol=1e-3)
    passing = {
        mode: run_tube(frames=3, speed=1.0, around=12, along=7, lead_in=1, settle_frames=1,
                       release=release, contact=ContactSettings(release=mode))
        for mode in ("never", "retry")
    }  # fmt: skip
    assert passing["retry"].bad == [False] * 3 and passing["retry"].released == [False] * 3
    np.testing.assert_array_equal(passing["retry"].points, passing["never"].points)


def test_the_t_shirts_torso_panels_are_released_from_the_arms() -> None:
    """``arm_release``: the T-shirt's torso particles (not its sleeves) against the arms' skin
    (shoulder to hand, not the trunk)."""
    from usd_garment.body.io import load_body_model
    from usd_garment.garment.library import load_template
    from usd_garment.methods.simulation import arm_release

    body = load_body_model(None)
    shirt = load_template("tshirt", "low")
    release = arm_release(body, shirt)
    x, y = shirt.vertices[:, 0], shirt.vertices[:, 1]
    assert not release.particles[np.argmax(np.abs(x))]  # a sleeve's cuff
    assert release.particles[np.argmin(y)]  # the hem
    assert 0.5 < release.particles.mean() < 0.95
    joint = body.weights.numpy().argmax(axis=1)
    assert release.body_vertices[joint == 22].all() and not release.body_vertices[joint == 0].any()


@pytest.mark.slow
def test_denser_tube_fast_motion() -> None:
    """1200 vertices, 3 s of a swing reaching ~1.6 m/s: whipping soft cotton stretches it."""
    result = run_tube(frames=90, speed=2.5, around=48, along=25)
    assert_good(result, 90, max_stretch=1.2)


@pytest.mark.parametrize(
    "betas",
    [[2.0], [-2.0], list(np.random.default_rng(3).normal(size=4))],
    ids=["beta1=+2", "beta1=-2", "beta1..4~N(0,1)"],
)
def test_lead_in_matches_the_graded_rest_shape(betas: list[float]) -> None:
    """A strong body shape does not break the first frame: the start (the draped template
    graded like the rest shape, on the shaped T-pose body) has the graded rest lengths, up to
    the drape's own sag (T-shirt low: rest-length error p99 4.5 %)."""
    from usd_garment.body.io import load_body_model
    from usd_garment.garment.library import load_template
    from usd_garment.methods.simulation import SimulationMethod
    from usd_garment.motion.sequence import SmplMotion

    shape = np.zeros(10, np.float32)
    shape[: len(betas)] = betas
    pose = np.zeros((1, 24, 3), np.float32)
    pose[:, 16, 2], pose[:, 17, 2] = -0.3, 0.3
    motion = SmplMotion(shape, pose, np.zeros((1, 3), np.float32), 30.0)
    method = SimulationMethod(lead_in=2, settle=0, max_substeps=4)
    method.predict(motion, load_body_model(None), load_template("tshirt", "low"))
    assert method.result is not None and method.result.ok
    first = method.result.lead_in_checks[0]
    assert first.stretch_p99 < 1.06 and first.inside_elsewhere_share < 0.002
    assert method.settings["lead_in_stretch_p99_first"] == pytest.approx(first.stretch_p99)


def test_root_glide_brings_the_root_up_to_the_first_velocity() -> None:
    """Before a motion that starts at 3.3 m/s the root speeds up from rest smoothly and ends
    where, and as fast as, the motion starts; a motion that starts at rest keeps it still."""
    from usd_garment.methods.simulation import root_glide

    fps, velocity = 30.0, np.array([3.3, 0.2, -0.5])
    trans = np.array([[0.4, 0.9, 0.1]]) + np.arange(3)[:, None] * velocity / fps
    glide = root_glide(trans, fps, 20)
    assert glide.shape == (21, 3)
    steps = np.diff(np.concatenate([glide, trans[:1]]), axis=0) * fps  # (21, 3) m/s
    speed = np.linalg.norm(steps, axis=1)
    assert speed[0] < 0.01 * np.linalg.norm(velocity)
    assert np.all(np.diff(speed) > 0)
    np.testing.assert_allclose(steps[-1], velocity, atol=1e-9)
    np.testing.assert_allclose(root_glide(trans[:1], fps, 20), np.repeat(trans[:1], 21, 0))
    still = np.repeat(trans[:1], 3, axis=0)
    np.testing.assert_allclose(root_glide(still, fps, 5), np.repeat(trans[:1], 6, 0))


def test_a_motion_that_starts_running_keeps_the_garment_on() -> None:
    """A motion that starts at 3.5 m/s (a capture cut mid-run, as CMU 09_01): the warm-up brings
    the body up to that speed, so no motion frame leaves a vertex farther than the good-frame
    limit from the body (held at its start, the body ran from the cloth: 12.7 cm by frame 2)."""
    from usd_garment.body.io import load_body_model
    from usd_garment.garment.library import load_template
    from usd_garment.methods.simulation import SimulationMethod
    from usd_garment.motion.sequence import SmplMotion

    pose = np.zeros((3, 24, 3), np.float32)
    pose[:, 16, 2], pose[:, 17, 2] = -1.2, 1.2
    trans = np.zeros((3, 3), np.float32)
    trans[:, 2] = np.arange(3) * 3.5 / 30.0
    motion = SmplMotion(np.zeros(10, np.float32), pose, trans, 30.0)
    method = SimulationMethod(lead_in=4, settle=2, max_substeps=4)
    method.predict(motion, load_body_model(None), load_template("tshirt", "low"))
    assert method.result is not None and method.result.ok
    limit = CheckLimits.for_garment("tshirt").far_distance
    assert max(check.max_distance for check in method.result.checks) <= limit


def test_a_teleport_within_one_motion_is_simulated_as_the_motion_moved() -> None:
    """A body walking 1 m/s that teleports 0.5 m and turns 90° about the up axis at frame 3 (a
    jump of the root alone, ``root_cuts``) is simulated with the jump taken out and the garment
    put back after: the garment is the jump-free motion's before the jump and that garment
    moved after it (left to the cloth, a 0.5 m step in one frame leaves it behind: "fell
    off")."""
    import torch
    from scipy.spatial.transform import Rotation

    from usd_garment.body.io import load_body_model
    from usd_garment.garment.library import load_template
    from usd_garment.methods.simulation import SimulationMethod
    from usd_garment.motion.cuts import root_cuts
    from usd_garment.motion.sequence import SmplMotion

    pose = np.zeros((6, 24, 3), np.float32)
    pose[:, 16, 2], pose[:, 17, 2] = -1.2, 1.2
    trans = np.zeros((6, 3), np.float32)
    trans[:, 2] = np.arange(6) / 30.0
    free = SmplMotion(np.zeros(10, np.float32), pose, trans, 30.0)
    turn = Rotation.from_rotvec([0.0, np.pi / 2, 0.0])
    body, template = load_body_model(None), load_template("tshirt", "low")
    pelvis = body.shaped(torch.zeros(1, 10))[1][0, 0].double().numpy()
    jumped_pose, jumped_trans = pose.copy(), trans.copy()
    jumped_pose[3:, 0] = turn.as_rotvec()
    # the body turned about its pelvis at frame 3 and moved 0.5 m: R(x - J0) + J0 + t turned
    jumped_trans[3:] = turn.apply(trans[3:] + pelvis) - pelvis + np.array([0.5, 0.0, 0.0])
    jumped = SmplMotion(free.betas, jumped_pose, jumped_trans, 30.0)
    assert root_cuts(jumped) == (3,)
    method = SimulationMethod(lead_in=4, settle=2, max_substeps=4)
    got = method.predict(jumped, body, template)
    assert method.result is not None and method.result.ok
    want = method.predict(free, body, template)
    np.testing.assert_allclose(got[:3], want[:3], atol=1e-3)
    moved = turn.apply(want[3:].reshape(-1, 3)).reshape(3, -1, 3) + np.array([0.5, 0.0, 0.0])
    np.testing.assert_allclose(got[3:], moved, atol=1e-3)  # 0.2 mm here


def test_a_restart_is_simulated_from_a_lead_in_of_its_own() -> None:
    """Two clips joined end to end with the cut declared (a restart: another motion starts) are
    simulated as each clip alone, the second from a lead-in of its own: the same garment, frame
    for frame, and the runs' checks and lead-ins in order in one result."""
    from usd_garment.body.io import load_body_model
    from usd_garment.garment.library import load_template
    from usd_garment.methods.simulation import SimulationMethod
    from usd_garment.motion.cuts import motion_restarts
    from usd_garment.motion.sequence import SmplMotion

    pose = np.zeros((6, 24, 3), np.float32)
    pose[:3, 16, 2], pose[:3, 17, 2] = -1.2, 1.2  # arms half lowered
    pose[3:, 16, 2], pose[3:, 17, 2] = -0.3, 0.3  # then nearly in the T-pose
    trans = np.zeros((6, 3), np.float32)
    trans[:, 2] = np.arange(6) / 30.0
    joined = SmplMotion(np.zeros(10, np.float32), pose, trans, 30.0, cut_times=(3.0,))
    assert motion_restarts(joined) == (3,)
    body, template = load_body_model(None), load_template("tshirt", "low")
    method = SimulationMethod(lead_in=4, settle=2, max_substeps=4)
    got = method.predict(joined, body, template)
    assert method.result is not None and method.result.ok
    assert len(method.result.checks) == 6 and len(method.result.lead_in_checks) == 2 * 6
    first = method.predict(SmplMotion(joined.betas, pose[:3], trans[:3], 30.0), body, template)
    second = method.predict(SmplMotion(joined.betas, pose[3:], trans[3:], 30.0), body, template)
    np.testing.assert_array_equal(got, np.concatenate([first, second]))


def test_body_parts_are_closed_colliders() -> None:
    """Each body part's collider is closed over its holes; the parts fill the body."""
    from usd_garment.sim.cloth import _closed_part

    body = capsule()
    labels = (body.vertices[body.faces].mean(axis=1)[:, 0] > 0).astype(np.int64)
    volume = 0.0
    for label in (0, 1):
        part, faces = _closed_part(np.asarray(body.faces)[labels == label])
        mesh = trimesh.Trimesh(part.of(np.asarray(body.vertices)), faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and len(part.rims) == 1
        volume += mesh.volume
    assert volume == pytest.approx(body.volume, rel=1e-3)
    result = run_tube(frames=3, speed=1.0, around=12, along=7, lead_in=1, settle_frames=1,
                      body_parts=labels)  # fmt: skip
    assert_good(result, 3)
