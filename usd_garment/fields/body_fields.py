"""The diffused body fields at run time: skinning weights W̃(p), shape blendshape matrices B̃s(p)
and (when the body has them) pose blendshape matrices B̃p(p), plus the canonical body SDF, all
baked into grids with differentiable trilinear interpolation; and their file format.

Shapes: ``(..., N, 3)`` query points in the canonical space (β = 0, T-pose), metres; J = 24
joints, K = 10 betas, P = 207 pose features. Blendshape fields are per-point matrices, linear in
β (or in the pose features), so one evaluation serves every shape and frame.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from usd_garment.atomic import atomic_output
from usd_garment.body.joints import NUM_BETAS, NUM_JOINTS
from usd_garment.fields.grid import DenseGrid, SparseGrid
from usd_garment.npz_file import read_npz

#: Version of the fields file layout.
FORMAT_VERSION = 1
DEFAULT_FIELDS_FILE = "default_body_fields.npz"
NUM_POSE_FEATURES = 9 * (NUM_JOINTS - 1)


def default_fields_path() -> Path:
    """Path of the fields fitted to the embedded default body."""
    return Path(str(resources.files("usd_garment") / "data" / "fields" / DEFAULT_FIELDS_FILE))


def _add_rows(
    acc: list[torch.Tensor] | None, rows: torch.Tensor, parts: list[torch.Tensor]
) -> list[torch.Tensor]:
    """``acc`` (``(M, C)`` tensors) plus ``parts`` ``(R, C)`` at the distinct ``rows`` ``(R,)``;
    None stands for the first term, whose rows are all M."""
    if acc is None:
        return parts
    return [a.index_add_(0, rows, p) for a, p in zip(acc, parts, strict=True)]


def _contracted(shape_dirs: torch.Tensor, betas: torch.Tensor) -> torch.Tensor:
    """Grid node values of the shape blendshapes ``(R, 3·K)`` contracted with ``betas``
    ``(K,)``: the offsets ``(R, 3)`` (m) of that body shape."""
    return shape_dirs.reshape(-1, 3, NUM_BETAS) @ betas.to(shape_dirs)


def _normalized(raw: torch.Tensor) -> torch.Tensor:
    """Raw weight field values ``(..., J)`` to skinning weights: ≥ 0, rows summing to 1."""
    w = raw.clamp_min(0.0)
    return w / w.sum(-1, keepdim=True).clamp_min(1e-8)


#: Central-difference step of :meth:`BodyFields.linearized` (m).
LINEARIZATION_STEP = 2e-3
#: Points farther than this from their anchor (m) are looked up exactly by the tangent.
LINEARIZATION_RADIUS = 0.02
#: Lookups of the anchor points that :meth:`BodyFields.linearized` makes (value, ±step per axis).
LINEARIZATION_LOOKUPS = 7


class BodyFields(torch.nn.Module):
    """Diffused skinning fields of one body model in its canonical space (β = 0, T-pose).

    Fields live in sparse grids over bands around the body (finer near it) and a coarse dense
    grid over the whole box (used beyond the bands; clamped beyond the box); each band is
    blended into the coarser grids over its outermost cell, so the fields have no seams. The
    SDF lives in a fine sparse grid near the surface and a coarse dense grid; beyond the coarse
    box it returns the box's boundary value plus the distance to the box (an upper bound, so
    conservative).

    Args:
        field_levels: sparse grids, finest first, each with some of the groups ``weights`` (24),
            ``shape_dirs`` (30) and ``pose_dirs`` (621, optional); for each group a point reads
            the finest level holding that group whose band holds its cell (so the smooth
            blendshape fields can live on coarser levels than the weights).
        fields_coarse: dense grid with the same groups, for points outside every band.
        sdf_fine: sparse grid with group ``sdf`` (1).
        sdf_coarse: dense grid with group ``sdf`` (1).
        body_name: name of the body model the fields were fitted to.
        config: how the fields were made (JSON-serialisable).
        mlp_state: state of the fitted MLPs when the grids were baked from MLPs (kept for
            reference evaluations); None for grids baked directly from the diffusion.
    """

    def __init__(
        self,
        field_levels: list[SparseGrid],
        fields_coarse: DenseGrid,
        sdf_fine: SparseGrid,
        sdf_coarse: DenseGrid,
        body_name: str,
        config: dict[str, Any] | None = None,
        mlp_state: dict[str, np.ndarray] | None = None,
    ) -> None:
        super().__init__()
        self.field_levels = torch.nn.ModuleList(field_levels)
        self.fields_coarse = fields_coarse
        self.sdf_fine = sdf_fine
        self.sdf_coarse = sdf_coarse
        self.body_name = body_name
        self.config: dict[str, Any] = dict(config or {})
        self.mlp_state = mlp_state
        #: The last β's offset grids and their key, β and device (see :meth:`_offset_grids`).
        self._offsets: tuple[tuple[list[float], torch.device], list[SparseGrid], DenseGrid] | None
        self._offsets = None

    @property
    def has_pose_dirs(self) -> bool:
        return "pose_dirs" in self.fields_coarse.names

    def _fields(self, points: torch.Tensor, names: tuple[str, ...]) -> list[torch.Tensor]:
        """Values ``(..., N, C)`` of field groups at points ``(..., N, 3)``. Groups stored on the
        same levels are looked up together."""
        lead = points.shape[:-1]
        flat = points.reshape(-1, 3).to(self.fields_coarse.origin)
        by_levels: dict[tuple[int, ...], list[str]] = {}
        for name in names:
            held = tuple(i for i, level in enumerate(self.field_levels) if name in level.names)
            by_levels.setdefault(held, []).append(name)
        found: dict[str, torch.Tensor] = {}
        for held, group in by_levels.items():
            levels = [self.field_levels[i] for i in held]
            cascade = self._cascade(flat, tuple(group), levels, self.fields_coarse)
            found |= dict(zip(group, cascade, strict=True))
        return [found[n].reshape(*lead, found[n].shape[-1]) for n in names]

    @staticmethod
    def _cascade(
        flat: torch.Tensor, names: tuple[str, ...], levels: list[SparseGrid], coarse: DenseGrid
    ) -> list[torch.Tensor]:
        """Values ``(M, C)`` of groups at points ``(M, 3)``: each level's values blended over the
        coarser ones' with its blend weight (1 inside its band, falling to 0 over the band's
        outermost cell, so there is no seam where a band ends); the dense grid ``coarse`` last."""
        acc: list[torch.Tensor] | None = None
        remaining = flat.new_ones(flat.shape[0])  # weight left for coarser levels
        todo = torch.arange(flat.shape[0], device=flat.device)
        for level in levels:
            # The first level sees every point with all its weight left: no gathers.
            first = acc is None
            points = flat if first else flat.index_select(0, todo)
            left = remaining if first else remaining.index_select(0, todo)
            level_values, alpha = level.blended(points, names)
            share = left * alpha
            acc = _add_rows(acc, todo, [share[:, None] * v for v in level_values])
            if first:  # a new tensor: ``share`` keeps the first for its gradient
                remaining = left * (1 - alpha)
            else:
                remaining.index_put_((todo,), left * (1 - alpha))
            todo = todo[alpha < 1]
            if not todo.numel():
                break
        if acc is None or todo.numel():
            values = coarse(flat[todo], names)
            acc = _add_rows(acc, todo, [remaining[todo, None] * c for c in values])
        return acc

    def _shaped_raw(
        self, points: torch.Tensor, betas: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw weight field values ``(..., N, J)`` (see :meth:`weights` for their normalisation)
        and the shape offsets B̃s(X)·β ``(..., N, 3)`` (m) of one body shape ``betas`` ``(K,)``
        at points ``(..., N, 3)``: the values of :meth:`all_fields`, with the blendshape
        grids contracted with β before the lookup (3 channels gathered per corner instead of
        3K, about half the cost of looking up both groups)."""
        lead = points.shape[:-1]
        flat = points.reshape(-1, 3).to(self.fields_coarse.origin)
        (raw,) = self._fields(flat, ("weights",))
        return raw.reshape(*lead, -1), self.shape_offsets(flat, betas).reshape(*lead, 3)

    def shape_offsets(self, points: torch.Tensor, betas: torch.Tensor) -> torch.Tensor:
        """The shape offsets B̃s(X)·β ``(..., N, 3)`` (m) of :meth:`shaped` alone, at points
        ``(..., N, 3)`` (the weights cost more than half of a lookup of both). Zero for the
        template shape (β = 0, every BVH import's), with no lookup: the preimage search spent
        a sixth of its time on these offsets."""
        if not betas.requires_grad and not bool(betas.any()):
            return self.fields_coarse.origin.new_zeros(points.shape)
        flat = points.reshape(-1, 3).to(self.fields_coarse.origin)
        levels, coarse = self._offset_grids(betas)
        (offsets,) = self._cascade(flat, ("offset",), levels, coarse)
        return offsets.reshape(points.shape)

    def _offset_grids(self, betas: torch.Tensor) -> tuple[list[SparseGrid], DenseGrid]:
        """The levels holding ``shape_dirs`` and the dense grid with one channel group,
        ``offset`` ``(R, 3)`` (m): the blendshapes contracted with ``betas`` ``(K,)``. The last
        shape's grids are kept and reused while β is the same (a garment's posing and the
        preimage search look the fields up many times for one body); a β that needs gradients
        gets new ones."""
        key = (betas.detach().cpu().tolist(), self.fields_coarse.origin.device)
        last = self._offsets  # read once: another thread may replace it
        if last is not None and last[0] == key and not betas.requires_grad:
            return last[1], last[2]
        levels = [
            level.with_channels({"offset": _contracted(level.channel("shape_dirs"), betas)})
            for level in self.field_levels
            if "shape_dirs" in level.names
        ]
        dense = self.fields_coarse
        coarse = DenseGrid(
            dense.origin,
            dense.spacing,
            {"offset": _contracted(dense.channel("shape_dirs"), betas).reshape(*dense.shape, 3)},
        )
        if not betas.requires_grad:
            self._offsets = (key, levels, coarse)
        return levels, coarse

    def shaped(
        self, points: torch.Tensor, betas: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Skinning weights ``(..., N, J)`` and shape offsets B̃s(X)·β ``(..., N, 3)`` (m) of one
        body shape ``betas`` ``(K,)`` at points ``(..., N, 3)`` (as :meth:`FieldTangent.shaped`,
        exactly)."""
        raw, offsets = self._shaped_raw(points, betas)
        return _normalized(raw), offsets

    def weights(self, points: torch.Tensor) -> torch.Tensor:
        """Diffused skinning weights ``(..., N, 24)`` at points ``(..., N, 3)``; rows are ≥ 0 and
        sum to 1."""
        (w,) = self._fields(points, ("weights",))
        return _normalized(w)

    def shape_dirs(self, points: torch.Tensor) -> torch.Tensor:
        """Diffused shape blendshapes ``(..., N, 3, 10)`` (m per unit β) at points ``(..., N, 3)``;
        the offset for betas β is ``einsum('...nck,k->...nc', shape_dirs, β)``."""
        (s,) = self._fields(points, ("shape_dirs",))
        return s.reshape(*s.shape[:-1], 3, NUM_BETAS)

    def pose_dirs(self, points: torch.Tensor) -> torch.Tensor | None:
        """Diffused pose blendshapes ``(..., N, 3, 207)`` at points ``(..., N, 3)``, or None when
        the body has no pose blendshapes."""
        if not self.has_pose_dirs:
            return None
        (p,) = self._fields(points, ("pose_dirs",))
        return p.reshape(*p.shape[:-1], 3, NUM_POSE_FEATURES)

    @property
    def _all_names(self) -> tuple[str, ...]:
        if self.has_pose_dirs:
            return ("weights", "shape_dirs", "pose_dirs")
        return ("weights", "shape_dirs")

    def all_fields(
        self, points: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """``weights``, ``shape_dirs`` and ``pose_dirs`` at once (one grid lookup)."""
        return self._finish(self._fields(points, self._all_names))

    def linearized(
        self,
        anchor: torch.Tensor,
        step: float = LINEARIZATION_STEP,
        radius: float = LINEARIZATION_RADIUS,
    ) -> FieldTangent:
        """The fields and their spatial derivatives at the points ``anchor`` ``(N, 3)`` (central
        differences over ``step`` m): a first-order stand-in for :meth:`all_fields` at points
        within ``radius`` (m) of their anchor, which are looked up exactly farther out (7
        lookups of N points for a whole chunk of frames instead of one per frame: see
        :data:`LINEARIZATION_LOOKUPS`)."""
        offsets = torch.zeros(7, 1, 3, dtype=anchor.dtype, device=anchor.device)
        for axis in range(3):  # the anchor, then +step and -step along each axis
            offsets[1 + 2 * axis, 0, axis], offsets[2 + 2 * axis, 0, axis] = step, -step
        groups = self._fields(anchor + offsets, self._all_names)  # one lookup of 7 N points
        sizes = [g.shape[-1] for g in groups]
        values = torch.cat(groups, dim=-1)  # (7, N, C)
        derivative = (values[1::2] - values[2::2]) / (2.0 * step)  # (3, N, C)
        derivative = derivative.permute(1, 2, 0).contiguous()  # (N, C, 3)
        return FieldTangent(self, anchor, values[0], derivative, sizes, radius)

    def _finish(
        self, values: list[torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Raw field values (the groups of ``_all_names``) to weights (≥ 0, rows summing to 1),
        shape and pose blendshapes."""
        w = _normalized(values[0])
        s = values[1].reshape(*values[1].shape[:-1], 3, NUM_BETAS)
        p = None
        if self.has_pose_dirs:
            p = values[2].reshape(*values[2].shape[:-1], 3, NUM_POSE_FEATURES)
        return w, s, p

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance ``(..., N)`` (m) of points ``(..., N, 3)`` to the canonical body,
        negative inside."""
        lead = points.shape[:-1]
        flat = points.reshape(-1, 3).to(self.sdf_fine.origin)
        (d,), valid = self.sdf_fine(flat, ("sdf",))
        d = d[:, 0]
        missing = (~valid).nonzero().squeeze(1)
        if missing.numel():
            p = flat[missing]
            inside = p.clamp(self.sdf_coarse.origin, self.sdf_coarse.upper)
            (coarse,) = self.sdf_coarse(inside, ("sdf",))
            gap = (p - inside).square().sum(-1)
            outside = gap > 0
            gap = torch.where(outside, gap, torch.ones_like(gap)).sqrt() * outside
            d = d.index_put((missing,), coarse[:, 0] + gap)
        return d.reshape(lead)

    def summary(self) -> dict[str, Any]:
        """Sizes and settings, for ``usd-garment fields info``."""
        return {
            "body": self.body_name,
            "pose_dirs": self.has_pose_dirs,
            "field_levels": [
                {
                    "spacing_m": level.spacing,
                    "lattice": list(level.shape),
                    "band_nodes": int(level.mask.sum()),
                    "groups": list(level.names),
                }
                for level in self.field_levels
            ],
            "fields_coarse": {
                "spacing_m": self.fields_coarse.spacing,
                "lattice": list(self.fields_coarse.shape),
            },
            "sdf_grid": {
                "spacing_m": self.sdf_fine.spacing,
                "lattice": list(self.sdf_fine.shape),
                "band_nodes": int(self.sdf_fine.mask.sum()),
                "coarse_spacing_m": self.sdf_coarse.spacing,
                "coarse_lattice": list(self.sdf_coarse.shape),
            },
            "box_min_m": self.fields_coarse.origin.tolist(),
            "box_max_m": self.fields_coarse.upper.tolist(),
            "has_mlp": self.mlp_state is not None,
            "config": self.config,
        }


def _pack_sparse(prefix: str, grid: SparseGrid, out: dict[str, np.ndarray]) -> None:
    out[f"{prefix}/origin"] = grid.origin.cpu().numpy()
    out[f"{prefix}/spacing"] = np.float32(grid.spacing)
    out[f"{prefix}/shape"] = np.array(grid.shape, dtype=np.int64)
    out[f"{prefix}/mask"] = np.packbits(grid.mask.cpu().numpy().reshape(-1))
    for name in grid.names:
        out[f"{prefix}/{name}"] = grid.channel(name).cpu().numpy().astype(np.float16)


def _pack_dense(prefix: str, grid: DenseGrid, out: dict[str, np.ndarray]) -> None:
    out[f"{prefix}/origin"] = grid.origin.cpu().numpy()
    out[f"{prefix}/spacing"] = np.float32(grid.spacing)
    out[f"{prefix}/shape"] = np.array(grid.shape, dtype=np.int64)
    for name in grid.names:
        out[f"{prefix}/{name}"] = grid.channel(name).cpu().numpy().astype(np.float16)


def _group_names(data: dict[str, np.ndarray], prefix: str) -> list[str]:
    skip = {"origin", "spacing", "shape", "mask"}
    keys = [k.split("/", 1)[1] for k in data if k.startswith(prefix + "/")]
    return [k for k in keys if k not in skip]


def _unpack_sparse(prefix: str, data: dict[str, np.ndarray]) -> SparseGrid:
    shape = tuple(int(s) for s in data[f"{prefix}/shape"])
    count = int(np.prod(shape))
    mask = np.unpackbits(data[f"{prefix}/mask"], count=count).astype(bool).reshape(shape)
    channels = {
        n: torch.from_numpy(data[f"{prefix}/{n}"].astype(np.float32))
        for n in _group_names(data, prefix)
    }
    origin = torch.from_numpy(data[f"{prefix}/origin"])
    return SparseGrid(origin, float(data[f"{prefix}/spacing"]), torch.from_numpy(mask), channels)


def _unpack_dense(prefix: str, data: dict[str, np.ndarray]) -> DenseGrid:
    shape = tuple(int(s) for s in data[f"{prefix}/shape"])
    channels = {
        n: torch.from_numpy(data[f"{prefix}/{n}"].astype(np.float32).reshape(*shape, -1))
        for n in _group_names(data, prefix)
    }
    origin = torch.from_numpy(data[f"{prefix}/origin"])
    return DenseGrid(origin, float(data[f"{prefix}/spacing"]), channels)


def save_body_fields(path: str | Path, fields: BodyFields) -> None:
    """Write ``fields`` as a compressed ``.npz`` (grid values and any MLP state in float16),
    atomically."""
    out: dict[str, np.ndarray] = {
        "version": np.array(FORMAT_VERSION),
        "body_name": np.array(fields.body_name),
        "config": np.array(json.dumps(fields.config)),
    }
    out["field_levels"] = np.array(len(fields.field_levels))
    for i, level in enumerate(fields.field_levels):
        _pack_sparse(f"fields_{i}", level, out)
    _pack_dense("fields_coarse", fields.fields_coarse, out)
    _pack_sparse("sdf_fine", fields.sdf_fine, out)
    _pack_dense("sdf_coarse", fields.sdf_coarse, out)
    for key, value in (fields.mlp_state or {}).items():
        out[f"mlp/{key}"] = np.asarray(value, dtype=np.float16)
    with atomic_output(Path(path)) as tmp, tmp.open("wb") as fh:
        np.savez_compressed(fh, **out)


def load_body_fields(path: str | Path | None = None) -> BodyFields:
    """Load fields written by :func:`save_body_fields`; ``None`` loads the default body's.

    Raises:
        ValueError: the file is missing or is not a body fields file of this version.
    """
    path = default_fields_path() if path is None else Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such body fields file")
    data = read_npz(path, "cannot read body fields")
    if "version" not in data or "field_levels" not in data:
        raise ValueError(f"{path}: not a body fields file")
    if int(data["version"]) != FORMAT_VERSION:
        raise ValueError(f"{path}: body fields version {int(data['version'])} is not supported")
    mlp = {
        k.split("/", 1)[1]: v.astype(np.float32) for k, v in data.items() if k.startswith("mlp/")
    }
    fields = BodyFields(
        [_unpack_sparse(f"fields_{i}", data) for i in range(int(data["field_levels"]))],
        _unpack_dense("fields_coarse", data),
        _unpack_sparse("sdf_fine", data),
        _unpack_dense("sdf_coarse", data),
        body_name=str(data["body_name"]),
        config=json.loads(str(data["config"])),
        mlp_state=mlp or None,
    )
    if fields.fields_coarse.channel("weights").shape[1] != NUM_JOINTS:
        raise ValueError(f"{path}: the weights field does not have 24 joints")
    return fields


@dataclass
class FieldTangent:
    """The body fields to first order about anchor points: ``value + derivative · (x − anchor)``.

    Attributes:
        fields: the fields it was taken from.
        anchor: ``(N, 3)`` points (m).
        value: ``(N, C)`` raw field values there (every group, concatenated).
        derivative: ``(N, C, 3)`` their derivatives (per m).
        sizes: channels of each group of ``value``.
        radius: points farther than this from their anchor (m) are looked up exactly.
    """

    fields: BodyFields
    anchor: torch.Tensor
    value: torch.Tensor
    derivative: torch.Tensor
    sizes: list[int]
    radius: float = LINEARIZATION_RADIUS

    def far_count(self, points: torch.Tensor) -> int:
        """How many of the points ``(B, N, 3)`` lie farther than ``radius`` from their anchor
        (each an exact lookup for :meth:`all_fields` and :meth:`shaped`)."""
        return int(((points - self.anchor).norm(dim=-1) > self.radius).sum())

    def all_fields(
        self, points: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """As :meth:`BodyFields.all_fields` for points ``(B, N, 3)``: to first order within
        ``radius`` of the anchor, exactly beyond."""
        delta = points - self.anchor
        raw = self.value + torch.einsum("nck,bnk->bnc", self.derivative, delta)
        far = delta.norm(dim=-1) > self.radius
        if bool(far.any()):
            raw[far] = torch.cat(self.fields._fields(points[far], self.fields._all_names), dim=-1)
        return self.fields._finish(list(torch.split(raw, self.sizes, dim=-1)))

    def shaped(
        self, points: torch.Tensor, betas: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Skinning weights ``(B, N, J)`` and the shape offsets B̃s(X)·β ``(B, N, 3)`` (m) of one
        body shape ``betas`` ``(K,)`` at points ``(B, N, 3)``, to first order as
        :meth:`all_fields` (exactly beyond ``radius``). The blendshapes are contracted with β
        before the frames are, so a frame costs J + 3 channels instead of J + 3K.
        """
        n, j, k = self.anchor.shape[0], self.sizes[0], NUM_BETAS
        shape_value = _contracted(self.value[:, j : j + 3 * k], betas)  # (N, 3)
        shape_derivative = torch.einsum(
            "nckd,k->ncd", self.derivative[:, j : j + 3 * k].reshape(n, 3, k, 3), betas
        )  # (N, 3, 3)
        value = torch.cat([self.value[:, :j], shape_value], dim=-1)  # (N, J + 3)
        derivative = torch.cat([self.derivative[:, :j], shape_derivative], dim=1)
        planes = derivative.permute(2, 0, 1).contiguous()  # (3, N, J + 3): d/dx, d/dy, d/dz
        delta = points - self.anchor
        raw = torch.addcmul(value, planes[0], delta[..., 0:1])  # (B, N, J + 3)
        for axis in (1, 2):
            raw.addcmul_(planes[axis], delta[..., axis : axis + 1])
        far = delta.norm(dim=-1) > self.radius
        if bool(far.any()):
            raw[far] = torch.cat(self.fields._shaped_raw(points[far], betas), dim=-1)
        return _normalized(raw[..., :j]), raw[..., j:]
