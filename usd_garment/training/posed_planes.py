"""The posed body's collision planes of a canonical training set, pulled back to canonical space:
a collision term in posed space that costs no posing at training time.

For each frame, the target garment X is posed with the garment model (``y = M_G(X, β, θ)``) and
queried against the posed body (winding-number inside test, closest point p, pseudo-normal n).
Each vertex within ``radius`` of the body whose closest point is not forced (not inside another
part of the body) keeps the half-space ``(y − p)·n ≥ ε``. Near X the garment model is, per
vertex, an affine map ``y(x) ≈ A x + k`` (its fields frozen at X: A is the blend of the joints'
rotations by the skinning weights W̃(X)), so the half-space reads ``a·x + c ≥ ε`` for a
canonical vertex x, with ``a = Aᵀ n`` and ``c = (y − A X − p)·n`` (m). A decoded canonical
garment is then held out of the posed body by a dot product per vertex.

Shapes: T frames of the set, N garment vertices. Units: metres.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from usd_garment.atomic import atomic_output
from usd_garment.body.model import BodyModel
from usd_garment.canonical.dataset import CanonicalSet
from usd_garment.eval.body_distance import BodyPool, BodySurface, signed_distance
from usd_garment.fields.body_fields import BodyFields
from usd_garment.garment.model import GarmentModel

#: Vertices farther than this from the posed body (m) get no plane.
PLANE_RADIUS = 0.02
#: Frames posed at once.
_POSE_FRAMES = 32


@dataclass
class PosedPlanes:
    """Half-spaces ``a·x + c ≥ ε`` of every frame's canonical vertices.

    Attributes:
        normal: ``(T, N, 3)`` a = Aᵀn (unitless; zero where there is no plane).
        offset: ``(T, N)`` c (m; zero where there is no plane).
        valid: ``(T, N)`` bool, whether the vertex has a plane in that frame.
    """

    normal: torch.Tensor
    offset: torch.Tensor
    valid: torch.Tensor

    def distance(self, frames: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """Signed distances ``(F, N)`` (m, to first order) of canonical garments ``x``
        ``(F, N, 3)`` to their frames' planes (``frames``: ``(F,)`` indices into the set);
        meaningful where :attr:`valid` is set."""
        return (self.normal[frames] * x).sum(-1) + self.offset[frames]

    def loss(self, frames: torch.Tensor, x: torch.Tensor, epsilon: float) -> torch.Tensor:
        """Σ_i max(ε − d_i, 0) over the vertices with a plane, averaged over the frames (m):
        zero when every such vertex is at least ε (m) outside its plane."""
        gap = (epsilon - self.distance(frames, x)).clamp_min(0.0)
        return (gap * self.valid[frames]).sum(-1).mean()

    def inside(self, frames: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """``(F, N)`` bool: the vertex has a plane and lies behind it."""
        return self.valid[frames] & (self.distance(frames, x) < 0)


def posed_planes(
    data: CanonicalSet,
    body: BodyModel,
    fields: BodyFields,
    splits: Sequence[str] = ("train", "validation"),
    radius: float = PLANE_RADIUS,
    pool: BodyPool | None = None,
    progress: Callable[[int, int], None] | None = None,
    known: PosedPlanes | None = None,
) -> PosedPlanes:
    """The planes of the frames of ``data``'s sequences in ``splits`` (the other frames get
    none). ``pool``: worker processes for the body queries; ``progress(done, total)`` after each
    sequence. ``known``: the planes of ``data``'s first sequences (their T₀ frames, made with
    the same splits and radius: :func:`reusable_posed_planes`), kept; only the others are
    computed."""
    garment_model = GarmentModel(body, fields)
    surface = BodySurface(body.faces.numpy(), body.num_vertices)
    t_frames, n = data.canonical.shape[:2]
    normal = torch.zeros((t_frames, n, 3))
    offset = torch.zeros((t_frames, n))
    valid = torch.zeros((t_frames, n), dtype=torch.bool)
    kept = 0 if known is None else len(known.valid)
    if known is not None:
        normal[:kept], offset[:kept], valid[:kept] = known.normal, known.offset, known.valid
    chosen = [
        s for s, split in enumerate(data.splits)
        if split in splits and data.frame_offsets[s + 1] > kept
    ]  # fmt: skip
    for done, s in enumerate(chosen):
        frames = data.sequence(s)
        motion = data.motion(s)
        x = torch.as_tensor(np.asarray(data.canonical[frames], dtype=np.float32))
        with torch.no_grad():
            betas, pose = torch.from_numpy(motion.betas), torch.from_numpy(motion.pose)
            trans = torch.from_numpy(motion.trans)
            art = garment_model.articulation(betas, pose, trans)
            y, a = [], []
            for i in range(0, len(x), _POSE_FRAMES):
                part = slice(i, i + _POSE_FRAMES)
                out = garment_model.pose(x[part], art[part])
                y.append(out.vertices)
                rotations = art.transforms[part, :, :3, :3]
                a.append(torch.einsum("bnj,bjxy->bnxy", out.weights, rotations))
            posed, linear = torch.cat(y), torch.cat(a)  # (t, N, 3), (t, N, 3, 3)
            query = signed_distance(
                posed, body(betas, pose, trans).vertices, surface, probe_below=radius, pool=pool
            )
            keep = torch.from_numpy((query.distance < radius) & ~query.closest_inside)
            n_body = torch.from_numpy(query.normal).float()
            p_body = torch.from_numpy(query.closest).float()
            k = posed - torch.einsum("bnxy,bny->bnx", linear, x)
            normal[frames] = torch.where(
                keep[..., None], torch.einsum("bnxy,bnx->bny", linear, n_body), 0.0
            )
            offset[frames] = torch.where(keep, ((k - p_body) * n_body).sum(-1), 0.0)
            valid[frames] = keep
        if progress is not None:
            progress(done + 1, len(chosen))
    return PosedPlanes(normal, offset, valid)


def _fingerprint(data: CanonicalSet, radius: float, sequences: int | None = None) -> str:
    """A digest of the set's first ``sequences`` sequences (None: all; their frames: every
    64th canonical garment, all poses, the sequence bounds, the splits) and the radius: planes
    are reused only for the set they were made from, or for a set that begins with it."""
    count = data.num_sequences if sequences is None else sequences
    end = int(data.frame_offsets[count])
    digest = hashlib.sha1()
    step = max(1, end // 64)
    arrays = (data.canonical[:end:step], data.pose[:end], data.trans[:end],
              data.frame_offsets[: count + 1])  # fmt: skip
    for array in arrays:
        digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    digest.update(repr((list(data.splits[:count]), radius)).encode())
    return digest.hexdigest()


def save_posed_planes(
    path: str | Path, planes: PosedPlanes, data: CanonicalSet, radius: float
) -> None:
    """Write ``planes`` of ``data`` (made with ``radius``) to an ``.npz`` (atomically)."""
    with atomic_output(Path(path)) as tmp, open(tmp, "wb") as f:
        np.savez(
            f, normal=planes.normal.numpy(), offset=planes.offset.numpy(),
            valid=planes.valid.numpy(), fingerprint=_fingerprint(data, radius),
        )  # fmt: skip


def reusable_posed_planes(
    path: str | Path, data: CanonicalSet, radius: float
) -> tuple[PosedPlanes, int]:
    """The planes saved by :func:`save_posed_planes` and how many of ``data``'s sequences they
    are for: all of them, or its first K when ``data`` grew from the set they were made for
    (``project --update`` appends sequences).

    Raises:
        ValueError: the file holds another set's or radius's planes (their large arrays are
            then not read).
    """
    with np.load(Path(path)) as f:
        valid = torch.from_numpy(f["valid"])  # the smallest array: its frames tell K
        ends = data.frame_offsets.tolist()
        count = ends.index(len(valid)) if len(valid) in ends[1:] else 0
        if count == 0 or str(f["fingerprint"]) != _fingerprint(data, radius, count):
            raise ValueError(f"{path}: posed planes of another training set (or radius)")
        planes = PosedPlanes(torch.from_numpy(f["normal"]), torch.from_numpy(f["offset"]), valid)
    return planes, count
