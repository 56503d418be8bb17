"""Derive the embedded default body (an SMPL-layout body) from the free ``anny`` model.

Run once to (re)build ``usd_garment/data/default_body.npz``; ``anny`` (the ``[anny]`` extra) is
imported only here and only when building. The steps, described in ``docs/default_body.md``:

1. sample adult Anny phenotypes (Anny's WHO-calibrated ``SimpleShapeDistribution``, ages 18-65);
2. re-pose each sample from Anny's A-pose to SMPL's T-pose with Anny's own skinning (arms along
   ±X, forearms and hands in line, legs nearly straight down), convert Z-up/−Y-facing to SMPL's
   Y-up/+Z-facing frame and put the pelvis at :data:`PELVIS_REST`;
3. keep the closed body surface (drop the separate eyeballs and mouth-interior piece);
4. merge Anny's bone weights onto the 24 SMPL joints (:data:`BONE_TO_JOINT`);
5. PCA of the rest meshes gives a 10-d shape space with unit-variance β;
6. fit a sparse, convex joint regressor that reproduces the joints of every sample.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.optimize import nnls
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from usd_garment.atomic import atomic_output
from usd_garment.body.io import save_body_model
from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS, SMPL_JOINT_NAMES
from usd_garment.body.model import BodyModel

#: Where the pelvis joint sits in the rest pose (m), about where SMPL's neutral template has it,
#: so AMASS root translations put the feet near the floor.
PELVIS_REST = np.array([0.0, -0.23, 0.0])

#: Anny (Z-up, facing −Y) to SMPL (Y-up, facing +Z): (x, y, z) -> (x, z, −y), a proper rotation.
ANNY_TO_SMPL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

#: Anny bone (left side and centre; ``.R`` bones mirror their ``.L`` twin) -> the SMPL joint
#: whose segment it belongs to. A name ending in ``*`` matches every bone with that prefix.
BONE_TO_JOINT: tuple[tuple[str, str], ...] = (
    ("root", "pelvis"),
    ("pelvis.L", "pelvis"),
    ("spine05", "pelvis"),
    ("upperleg01.L", "left_hip"),
    ("upperleg02.L", "left_hip"),
    ("lowerleg01.L", "left_knee"),
    ("lowerleg02.L", "left_knee"),
    ("foot.L", "left_ankle"),
    ("toe*.L", "left_foot"),
    ("spine04", "spine1"),
    ("spine03", "spine1"),
    ("spine02", "spine2"),
    ("spine01", "spine3"),
    ("clavicle.L", "left_collar"),
    ("shoulder01.L", "left_collar"),
    ("upperarm01.L", "left_shoulder"),
    ("upperarm02.L", "left_shoulder"),
    ("lowerarm01.L", "left_elbow"),
    ("lowerarm02.L", "left_elbow"),
    ("wrist.L", "left_wrist"),
    ("metacarpal*.L", "left_wrist"),
    ("finger*.L", "left_hand"),
    ("neck*", "neck"),
    ("head", "head"),
    ("eye.L", "head"),
    ("jaw", "head"),
    ("tongue*", "head"),
)

#: SMPL joint (left side and centre; right mirrors) -> the Anny bone heads it sits at (the mean
#: when several are listed).
JOINT_TO_BONE_HEADS: dict[str, tuple[str, ...]] = {
    "pelvis": ("root",),
    "left_hip": ("upperleg01.L",),
    "spine1": ("spine04",),
    "left_knee": ("lowerleg01.L",),
    "spine2": ("spine02",),
    "left_ankle": ("foot.L",),
    "spine3": ("spine01",),
    "left_foot": tuple(f"toe{i}-1.L" for i in range(1, 6)),
    "neck": ("neck01",),
    "left_collar": ("clavicle.L",),
    "head": ("head",),
    "left_shoulder": ("upperarm01.L",),
    "left_elbow": ("lowerarm01.L",),
    "left_wrist": ("wrist.L",),
    "left_hand": tuple(f"finger{i}-1.L" for i in range(2, 6)),
}

#: Outward tilt of the hip-to-ankle line from the vertical (deg). Anny's A-pose has 5.4°;
#: 4° keeps the thighs of the heaviest sampled bodies apart (fully vertical legs make them
#: interpenetrate), while SMPL's template has about 1.5°.
LEG_SPLAY_DEG = 4.0
_LEG_GOAL = (math.sin(math.radians(LEG_SPLAY_DEG)), 0.0, -math.cos(math.radians(LEG_SPLAY_DEG)))

#: Re-posing to the T-pose, left side (right mirrors x): each bone turns about its head, in
#: order, so that the vector from its head to the target bone's head points along the goal axis
#: (Anny's frame: +X the body's left, −Y forward, −Z down).
TPOSE_ALIGNMENTS: tuple[tuple[str, str, tuple[float, float, float]], ...] = (
    ("upperleg01.L", "foot.L", _LEG_GOAL),
    ("upperarm01.L", "lowerarm01.L", (1.0, 0.0, 0.0)),
    ("lowerarm01.L", "wrist.L", (1.0, 0.0, 0.0)),
    ("wrist.L", "finger3-1.L", (1.0, 0.0, 0.0)),
)

#: Adult morphological ages (years) sampled, uniformly.
AGE_RANGE_YEARS = (18.0, 65.0)


def _mirror(name: str) -> str:
    return name.replace(".L", ".R").replace("left_", "right_")


def _mirrored_pairs(pairs: tuple[tuple[str, str], ...]) -> list[tuple[str, str]]:
    out = list(pairs)
    out += [(_mirror(a), _mirror(b)) for a, b in pairs if ".L" in a]
    return out


def bone_joint_map(bone_labels: list[str]) -> np.ndarray:
    """SMPL joint index ``(n_bones,)`` of each Anny bone, from :data:`BONE_TO_JOINT`.

    Raises:
        ValueError: a bone the table does not cover (a new Anny rig).
    """
    joint_index = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}
    pairs = _mirrored_pairs(BONE_TO_JOINT)
    out = np.empty(len(bone_labels), dtype=np.int64)
    for b, label in enumerate(bone_labels):
        for pattern, joint in pairs:
            prefix, _, suffix = pattern.partition("*")
            hit = label == pattern or (
                "*" in pattern and label.startswith(prefix) and label.endswith(suffix)
            )
            if hit:
                out[b] = joint_index[joint]
                break
        else:
            raise ValueError(f"Anny bone '{label}' has no SMPL joint in BONE_TO_JOINT")
    return out


def joint_head_matrix(bone_labels: list[str]) -> np.ndarray:
    """``(24, n_bones)`` averaging matrix: SMPL joints = it @ Anny bone heads."""
    index = {label: i for i, label in enumerate(bone_labels)}
    table = dict(JOINT_TO_BONE_HEADS)
    table.update(
        {_mirror(j): tuple(_mirror(b) for b in bs) for j, bs in JOINT_TO_BONE_HEADS.items()}
    )
    out = np.zeros((NUM_JOINTS, len(bone_labels)))
    for j, name in enumerate(SMPL_JOINT_NAMES):
        heads = table[name]
        for bone in heads:
            out[j, index[bone]] = 1.0 / len(heads)
    return out


def _align(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Smallest rotations ``(B, 3, 3)`` taking directions ``a (B, 3)`` onto ``b (B, 3)``."""
    a = a / a.norm(dim=-1, keepdim=True)
    b = b / b.norm(dim=-1, keepdim=True)
    v = torch.cross(a, b, dim=-1)
    c = (a * b).sum(-1)
    zero = torch.zeros_like(c)
    k = torch.stack([zero, -v[:, 2], v[:, 1], v[:, 2], zero, -v[:, 0], -v[:, 1], v[:, 0], zero], -1)
    k = k.reshape(-1, 3, 3)
    eye = torch.eye(3, dtype=a.dtype).expand_as(k)
    return eye + k + (k @ k) / (1.0 + c)[:, None, None]


def tpose_bone_transforms(
    heads: torch.Tensor, parents: list[int], bone_labels: list[str]
) -> torch.Tensor:
    """World transforms ``(B, n_bones, 4, 4)`` that re-pose Anny's rest skeleton (bone heads
    ``(B, n_bones, 3)``, m) to the T-pose of :data:`TPOSE_ALIGNMENTS`; a bone not listed moves
    with its parent."""
    index = {label: i for i, label in enumerate(bone_labels)}
    steps = {}
    for bone, target, goal in TPOSE_ALIGNMENTS:
        right_goal = (-goal[0], goal[1], goal[2])
        for b, t, g in ((bone, target, goal), (_mirror(bone), _mirror(target), right_goal)):
            steps[index[b]] = (index[t], torch.tensor(g, dtype=heads.dtype))
    b, n = heads.shape[:2]
    eye = torch.eye(4, dtype=heads.dtype).expand(b, 4, 4)
    world: list[torch.Tensor] = []
    for c in range(n):
        g = eye if parents[c] < 0 else world[parents[c]]
        if c in steps:
            target, goal = steps[c]
            head = (g[:, :3, :3] @ heads[:, c, :, None])[..., 0] + g[:, :3, 3]
            direction = (g[:, :3, :3] @ (heads[:, target] - heads[:, c])[..., None])[..., 0]
            rot = _align(direction, goal.expand_as(direction))
            turn = eye.clone()
            turn[:, :3, :3] = rot
            turn[:, :3, 3] = head - (rot @ head[..., None])[..., 0]
            g = turn @ g
        world.append(g)
    return torch.stack(world, dim=1)


def largest_component(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Indices of the vertices of the largest face-connected component (sorted)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), (n_vertices,) * 2)
    _, labels = connected_components(graph, directed=False)
    used = np.zeros(n_vertices, dtype=bool)
    used[faces.ravel()] = True
    counts = np.bincount(labels[used])
    return np.flatnonzero(labels == np.argmax(counts))


def shape_space(
    meshes: np.ndarray, heights: np.ndarray, n_betas: int = NUM_BETAS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """PCA of rest meshes ``(N, V, 3)``.

    Returns:
        mean ``(V, 3)``, shapedirs ``(V, 3, n_betas)`` (directions × their std over the samples,
        so each β has unit variance; β₁ signed so that it grows with ``heights (N,)``) and the
        share of the variance each direction explains ``(n_betas,)``.
    """
    n, v, _ = meshes.shape
    flat = meshes.reshape(n, -1)
    mean = flat.mean(0)
    u, s, vt = np.linalg.svd(flat - mean, full_matrices=False)
    std = s[:n_betas] / np.sqrt(n - 1)
    dirs = vt[:n_betas] * std[:, None]
    coeffs = u[:, :n_betas] * np.sqrt(n - 1)  # β of each sample
    signs = np.sign(dirs[np.arange(n_betas), np.abs(dirs).argmax(1)])
    signs[0] = 1.0 if np.corrcoef(coeffs[:, 0], heights)[0, 1] >= 0 else -1.0
    dirs *= signs[:, None]
    explained = s[:n_betas] ** 2 / np.sum(s**2)
    return mean.reshape(v, 3), dirs.T.reshape(v, 3, n_betas), explained


def _surrounding_vertices(template: np.ndarray, point: np.ndarray, per_octant: int) -> np.ndarray:
    """The ``per_octant`` nearest vertices in each of the 8 octants around ``point``."""
    d = template - point
    octant = (d[:, 0] > 0) * 4 + (d[:, 1] > 0) * 2 + (d[:, 2] > 0)
    dist = np.linalg.norm(d, axis=1)
    picked = []
    for o in range(8):
        members = np.flatnonzero(octant == o)
        picked.append(members[np.argsort(dist[members])[:per_octant]])
    return np.concatenate(picked)


def fit_joint_regressor(
    meshes: np.ndarray, joints: np.ndarray, template: np.ndarray, per_octant: int = 8
) -> np.ndarray:
    """Sparse convex joint regressor ``(24, V)`` fitted over samples.

    Per joint: non-negative weights summing to 1 over the ``per_octant`` nearest template
    vertices in each octant around it (8 · per_octant candidates), least squares of
    ``weights @ meshes[s]`` against ``joints[s]`` over all samples.

    Args:
        meshes: ``(N, V, 3)`` rest meshes (m). joints: ``(N, 24, 3)`` their joints (m).
        template: ``(V, 3)`` mesh used to pick the candidate vertices.
    """
    n, v, _ = meshes.shape
    regressor = np.zeros((joints.shape[1], v))
    mean_joints = joints.mean(0)
    for j in range(joints.shape[1]):
        cand = _surrounding_vertices(template, mean_joints[j], per_octant)
        a = meshes[:, cand, :].transpose(0, 2, 1).reshape(n * 3, len(cand))
        b = joints[:, j, :].reshape(n * 3)
        scale = 10.0 * np.sqrt(n)  # sum-to-one as a heavily weighted extra equation
        a = np.vstack([a, scale * np.ones((1, len(cand)))])
        b = np.append(b, scale)
        w, _ = nnls(a, b, maxiter=50 * len(cand))
        regressor[j, cand] = w / w.sum()
    return regressor


def _sample_phenotypes(model: Any, samples: int, seed: int) -> dict[str, torch.Tensor]:
    from anny.shape_distribution import SimpleShapeDistribution

    with torch.random.fork_rng():
        torch.manual_seed(seed)
        ages = torch.distributions.Uniform(
            torch.tensor(AGE_RANGE_YEARS[0], dtype=model.dtype),
            torch.tensor(AGE_RANGE_YEARS[1], dtype=model.dtype),
        )
        dist = SimpleShapeDistribution(model, morphological_age_distribution=ages)
        _, phenotypes = dist.sample(samples)
    return phenotypes


def tposed_samples(
    samples: int, seed: int, batch: int = 16, progress: Callable[[int], None] | None = None
) -> dict[str, Any]:
    """Sample Anny phenotypes and return their T-posed rest meshes in SMPL's frame.

    Returns a dict: ``vertices (N, V0, 3)``, ``joints (N, 24, 3)`` (m, pelvis at
    :data:`PELVIS_REST`), ``faces (F0, 3)``, ``weights (V0, 24)`` merged skinning weights,
    ``phenotypes`` (name -> ``(N,)``), all over Anny's full vertex set V0.
    """
    try:
        anny = importlib.import_module("anny")
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(
            "building the default body needs the 'anny' package: pip install 'usd-garment[anny]'"
        ) from exc
    model = anny.Anny()
    labels = list(model.bone_labels)
    parents = list(model.bone_parents)
    phenotypes = _sample_phenotypes(model, samples, seed)
    head_matrix = torch.as_tensor(joint_head_matrix(labels), dtype=model.dtype)
    to_smpl = torch.as_tensor(ANNY_TO_SMPL, dtype=model.dtype)
    verts, joints = [], []
    with torch.no_grad():
        for start in range(0, samples, batch):
            ph = {k: v[start : start + batch] for k, v in phenotypes.items()}
            rest = model(phenotype_kwargs=ph)
            rest_poses = rest["rest_bone_poses"]
            world = tpose_bone_transforms(rest["rest_bone_heads"], parents, labels) @ rest_poses
            out = model(world, phenotype_kwargs=ph, pose_parameterization="world")
            j = (head_matrix @ world[..., :3, 3]) @ to_smpl.T
            offset = torch.as_tensor(PELVIS_REST, dtype=model.dtype) - j[:, :1]
            verts.append((out["vertices"] @ to_smpl.T + offset).numpy())
            joints.append((j + offset).numpy())
            if progress is not None:
                progress(len(ph["age"]))
    dense = np.zeros((model.template_vertices.shape[0], len(labels)))
    rows = np.arange(dense.shape[0])[:, None]
    np.add.at(dense, (rows, model.vertex_bone_indices.numpy()), model.vertex_bone_weights.numpy())
    merged = np.zeros((dense.shape[0], NUM_JOINTS))
    np.add.at(merged.T, bone_joint_map(labels), dense.T)
    return {
        "vertices": np.concatenate(verts),
        "joints": np.concatenate(joints),
        "faces": np.asarray(model.faces, dtype=np.int64),
        "weights": merged,
        "phenotypes": {k: v.numpy() for k, v in phenotypes.items()},
    }


def assemble_body(data: dict[str, Any]) -> tuple[BodyModel, dict[str, Any]]:
    """Build the SMPL-layout body from :func:`tposed_samples` output; also return figures."""
    keep = largest_component(data["faces"], data["vertices"].shape[1])
    new_index = np.full(data["vertices"].shape[1], -1)
    new_index[keep] = np.arange(len(keep))
    faces = new_index[data["faces"]]
    faces = faces[(faces >= 0).all(1)]
    meshes = data["vertices"][:, keep]
    joints = data["joints"]
    weights = data["weights"][keep]
    weights /= weights.sum(1, keepdims=True)
    heights = meshes[..., 1].max(1) - meshes[..., 1].min(1)
    mean, shapedirs, explained = shape_space(meshes, heights)
    regressor = fit_joint_regressor(meshes, joints, mean)
    fitted = np.einsum("jv,nvc->njc", regressor, meshes)
    err = np.linalg.norm(fitted - joints, axis=-1)
    model = BodyModel(
        mean.astype(np.float32),
        shapedirs.astype(np.float32),
        np.zeros((len(keep), 3, 0), dtype=np.float32),
        regressor.astype(np.float32),
        weights.astype(np.float32),
        faces,
        name="anny-default",
    )
    summary = {
        "samples": int(meshes.shape[0]),
        "vertices": len(keep),
        "faces": len(faces),
        "dropped_vertices": int(data["vertices"].shape[1] - len(keep)),
        "sample_height_m": [round(float(heights.min()), 4), round(float(heights.max()), 4)],
        "sample_phenotype_ranges": {
            k: [round(float(x.min()), 3), round(float(x.max()), 3)]
            for k, x in data["phenotypes"].items()
        },
        "explained_variance": [round(float(x), 4) for x in explained],
        "explained_variance_total": round(float(explained.sum()), 4),
        "joint_error_mean_mm": round(float(err.mean() * 1000), 3),
        "joint_error_max_mm": round(float(err.max() * 1000), 3),
        "joint_error_max_joint": SMPL_JOINT_NAMES[int(err.max(0).argmax())],
    }
    return model, summary


def build_default_body(
    output: Path,
    samples: int = 300,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Derive the default body from Anny and write it (atomically) to ``output`` (.npz).

    Args:
        output: the ``.npz`` to write. samples: number of sampled phenotypes (≥ 20).
        seed: RNG seed of the phenotype sampling. progress: called with the samples done.

    Returns:
        Summary figures (counts, variance explained, joint-regressor errors).

    Raises:
        ModuleNotFoundError: ``anny`` is not installed. ValueError: too few samples.
        FileNotFoundError: the output folder does not exist.
    """
    if samples < 2 * NUM_BETAS:
        raise ValueError(f"--samples must be at least {2 * NUM_BETAS}, got {samples}")
    if not Path(output).parent.is_dir():
        raise FileNotFoundError(f"{Path(output).parent}: output folder does not exist")
    model, summary = assemble_body(tposed_samples(samples, seed, progress=progress))
    meta = {
        "source": "anny (Apache-2.0 code, CC0 MakeHuman assets); see docs/default_body.md",
        "anny_version": importlib.metadata.version("anny"),
        "samples": str(samples),
        "seed": str(seed),
    }
    with atomic_output(output) as tmp:
        save_body_model(tmp, model, **meta)
    summary["file_bytes"] = Path(output).stat().st_size
    return summary
