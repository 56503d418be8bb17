"""Baked 3D grids with differentiable trilinear interpolation: the fast evaluator of the diffused
body fields and of the canonical body SDF.

A :class:`SparseGrid` stores values only at the lattice nodes of a band (a boolean mask over a
regular lattice); a :class:`DenseGrid` stores every node of a box. Both interpolate with a gather
of the 8 cell corners, so gradients flow to the query points through the trilinear weights. A
sparse grid also gives a blend weight that falls continuously to 0 at the edge of its band, so
that nested grids can be blended without seams.
Shapes: M query points, C channels; positions in metres.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np
import torch
from scipy import ndimage


@functools.lru_cache(maxsize=64)
def _lattice_constants(
    shape: tuple[int, int, int], dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The lattice's last node ``(3,)``, zero ``(3,)``, last cell ``(3,)`` (as ``dtype``), the
    flat index strides ``(3,)`` (as ``dtype`` where it holds every node index exactly, else
    float64) and the flat index offsets ``(8,)`` (int32) of a cell's eight corners
    (c = 4·dx + 2·dy + dz): made once per lattice, not per lookup (the preimage search looks
    grids up thousands of times)."""
    upper = torch.tensor(shape, dtype=dtype, device=device) - 1
    corners = itertools.product((0, 1), repeat=3)
    step = [(dx * shape[1] + dy) * shape[2] + dz for dx, dy, dz in corners]
    exact = 2 / torch.finfo(dtype).eps  # the dtype holds every integer up to this (2²⁴ in float32)
    index_dtype = dtype if shape[0] * shape[1] * shape[2] <= exact else torch.float64
    return (
        upper,
        torch.zeros_like(upper),
        upper - 1,
        torch.tensor([shape[1] * shape[2], shape[2], 1], dtype=index_dtype, device=device),
        torch.tensor(step, dtype=torch.int32, device=device),
    )


def _cell_and_weights(
    points: torch.Tensor, origin: torch.Tensor, spacing: float, shape: tuple[int, int, int]
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Flat lattice indices ``(M, 8)`` (int32) of the corners of each point's cell, the
    matching trilinear weights ``(M, 8)`` and ``(M,)`` bool, whether the point lies in the
    lattice box, for points ``(M, 3)``. Points are clamped to the lattice box (so the weights'
    gradient is zero outside it). Corner c = 4·dx + 2·dy + dz."""
    upper, zero, last, strides, step = _lattice_constants(shape, points.dtype, points.device)
    raw = (points - origin) / spacing
    g = torch.clamp(raw, min=zero, max=upper)
    # The cell carries no gradient: detached where there is a graph, and only there (a detach is
    # an operation too: the preimage search's later passes look up a few hundred points at a
    # time, where each costs about as much as the work); a comparison carries none anyway.
    fixed = g.detach() if g.requires_grad else g
    # In the box where clamping leaves all three as they are (NaN is not); the three columns
    # and-ed, as a reduction over a short last dimension is several times slower.
    same = g == raw
    inside = same[:, 0] & same[:, 1] & same[:, 2]
    cell = torch.fmin(fixed.floor(), last)  # a NaN point's cell is the last one: in range
    t = (g - cell).t()  # (3, M) in [0, 1]
    ends = torch.stack((1 - t, t))  # (2, 3, M): the weights of the lower and upper corners
    # The eight products (x·y)·z as one (2, 2, 2, M) broadcast over rows of M (a few ops
    # whatever M: the preimage search looks up a few hundred points dozens of times a chunk),
    # then copied into the columns of an (M, 8) (a third of the time of a contiguous copy of
    # the transpose); the indices in int32 (a lattice has fewer than 2³¹ nodes) by one broadcast
    # sum (their column writes took three times longer on 229k points), the cell's flat index by
    # one product with the strides (exact: see _lattice_constants; ten times faster on 100k
    # points than sums of the int columns).
    w = (ends[:, None, 0] * ends[None, :, 1])[:, :, None] * ends[None, None, :, 2]
    weights = points.new_empty(points.shape[0], 8)
    weights.t().copy_(w.reshape(8, -1))
    base = (cell.to(strides.dtype) @ strides).int()
    return base[:, None] + step, weights, inside


def _interpolate(w: torch.Tensor, table: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
    """``(M, C)``: the rows ``(M, 8)`` of ``table`` ``(R, C)`` weighted by ``w`` ``(M, 8)``, as
    one fused weighted gather (``embedding_bag``: no ``(M, 8, C)`` temporary of corner values,
    which made a gather and a product an order of magnitude slower on a CPU). Differentiable
    once in ``w`` and ``table``; a single channel's gradient in ``w`` by
    :class:`_SingleChannelGather`."""
    if table.shape[1] == 1 and w.requires_grad and not table.requires_grad:
        return _SingleChannelGather.apply(w, table, rows)
    return torch.nn.functional.embedding_bag(rows, table, per_sample_weights=w, mode="sum")


class _SingleChannelGather(torch.autograd.Function):
    """``embedding_bag``'s weighted sum of one channel's rows, whose gradient in the weights
    ``(M, 8)`` is the corner values times the output's gradient: one gather. Torch's own
    (``_embedding_bag_per_sample_weights_backward``) took six times as long on 282,000 points
    (205 against 32 ms, the size of one of the VAE's collision terms; stop 93) for the same
    values to the bit. The table gets no gradient: a grid's values are constants."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: torch.autograd.function.FunctionCtx,
        w: torch.Tensor,
        table: torch.Tensor,
        rows: torch.Tensor,
    ) -> torch.Tensor:
        ctx.save_for_backward(table, rows)
        return torch.nn.functional.embedding_bag(rows, table, per_sample_weights=w, mode="sum")

    @staticmethod
    def backward(  # type: ignore[override]
        ctx: torch.autograd.function.FunctionCtx, grad: torch.Tensor
    ) -> tuple[torch.Tensor, None, None]:
        table, rows = ctx.saved_tensors  # type: ignore[attr-defined]
        corners = table.view(-1).index_select(0, rows.reshape(-1)).view(rows.shape)
        return corners * grad, None, None


def _register_channels(module: torch.nn.Module, channels: dict[str, torch.Tensor]) -> None:
    for name, values in channels.items():
        module.register_buffer(f"values_{name}", values.float().reshape(-1, values.shape[-1]))


class DenseGrid(torch.nn.Module):
    """Named channel groups at the nodes ``origin + spacing · (i, j, k)`` of a box.

    Args:
        origin: ``(3,)`` position of node (0, 0, 0) (m).
        spacing: node spacing (m).
        channels: name → ``(nx, ny, nz, C)`` node values.

    Points outside the box read the value at their clamped position (border extension).
    """

    origin: torch.Tensor

    def __init__(
        self, origin: torch.Tensor, spacing: float, channels: dict[str, torch.Tensor]
    ) -> None:
        super().__init__()
        first = next(iter(channels.values()))
        self.spacing = float(spacing)
        self.shape: tuple[int, int, int] = tuple(int(s) for s in first.shape[:3])  # type: ignore[assignment]
        self.names = tuple(channels)
        self.register_buffer("origin", torch.as_tensor(origin, dtype=torch.float32))
        _register_channels(self, channels)

    def channel(self, name: str) -> torch.Tensor:
        """``(nx·ny·nz, C)`` node values of one channel group."""
        return getattr(self, f"values_{name}")

    @property
    def upper(self) -> torch.Tensor:
        """``(3,)`` upper corner of the box (m); ``origin`` is the lower one."""
        n = torch.tensor(self.shape, dtype=self.origin.dtype, device=self.origin.device)
        return self.origin + self.spacing * (n - 1)

    def forward(self, points: torch.Tensor, names: tuple[str, ...]) -> list[torch.Tensor]:
        """Interpolated values ``(M, C)`` of each named group at points ``(M, 3)``."""
        flat, w, _ = _cell_and_weights(points, self.origin, self.spacing, self.shape)
        return [_interpolate(w, self.channel(n), flat) for n in names]


class SparseGrid(torch.nn.Module):
    """Named channel groups at the masked nodes of a lattice ``origin + spacing · (i, j, k)``.

    Args:
        origin: ``(3,)`` position of node (0, 0, 0) (m).
        spacing: node spacing (m).
        mask: ``(nx, ny, nz)`` bool, the nodes that hold values.
        channels: name → ``(mask.sum(), C)`` values of the masked nodes in C-order.
    """

    origin: torch.Tensor
    index: torch.Tensor

    def __init__(
        self,
        origin: torch.Tensor,
        spacing: float,
        mask: torch.Tensor,
        channels: dict[str, torch.Tensor],
    ) -> None:
        super().__init__()
        flat = mask.detach().cpu().numpy().reshape(-1).astype(bool, copy=False)
        count = int(np.count_nonzero(flat))  # numpy: several times faster than torch on bools
        if any(v.shape[0] != count for v in channels.values()):
            raise ValueError("a sparse grid needs one value row per masked node")
        self.spacing = float(spacing)
        self.shape: tuple[int, int, int] = tuple(int(s) for s in mask.shape)  # type: ignore[assignment]
        self.names = tuple(channels)
        index = np.full(flat.size, -1, dtype=np.int32)  # half the memory of int64 to fill
        index[flat] = np.arange(count, dtype=np.int32)
        self.register_buffer("origin", torch.as_tensor(origin, dtype=torch.float32))
        self.register_buffer("index", torch.from_numpy(index).to(mask.device))
        self._inner: torch.Tensor | None = None  # made by the first blended lookup
        _register_channels(self, channels)

    def channel(self, name: str) -> torch.Tensor:
        """``(mask.sum(), C)`` node values of one channel group."""
        return getattr(self, f"values_{name}")

    @property
    def mask(self) -> torch.Tensor:
        """``(nx, ny, nz)`` bool mask of the nodes that hold values."""
        return (self.index >= 0).reshape(self.shape)

    def forward(
        self, points: torch.Tensor, names: tuple[str, ...]
    ) -> tuple[list[torch.Tensor], torch.Tensor]:
        """Interpolated values ``(M, C)`` of each named group at points ``(M, 3)``, and ``(M,)``
        bool: whether the point lies in the lattice and all 8 corners of its cell hold values
        (rows where it is False are meaningless)."""
        values, valid, _, _ = self._lookup(points, names)
        return values, valid

    def with_channels(self, channels: dict[str, torch.Tensor]) -> SparseGrid:
        """A grid over the same nodes and band holding ``channels`` (name → ``(mask.sum(), C)``)
        instead of this one's."""
        grid = SparseGrid(self.origin, self.spacing, self.mask, channels)
        grid._inner = self.inner()
        return grid

    def inner(self) -> torch.Tensor:
        """``(mask.sum(), 1)`` float: 1 at the masked nodes whose 26 neighbours are all masked
        (nodes outside the lattice are not), else 0; made on first use (an erosion of the
        mask: a few hundred ms on the finest grids, which plain lookups never need)."""
        if self._inner is None or self._inner.device != self.index.device:
            mask = self.mask.cpu().numpy()
            box = np.ones((3, 3, 3), dtype=bool)
            eroded = ndimage.binary_erosion(mask, structure=box, border_value=0)
            inner = torch.from_numpy(eroded[mask]).float()[:, None]
            self._inner = inner.to(self.index.device)
        return self._inner

    def blended(
        self, points: torch.Tensor, names: tuple[str, ...]
    ) -> tuple[list[torch.Tensor], torch.Tensor]:
        """Like :meth:`forward`, with ``(M,)`` blend weights instead of the validity: the
        interpolation of 1 at the nodes inside the band (all 26 neighbours masked) and 0 at
        its edge nodes; continuous, 1 deep in the band, 0 where the point is not valid."""
        values, valid, w, rows = self._lookup(points, names)
        alpha = _interpolate(w, self.inner(), rows)[:, 0]
        return values, alpha * valid

    def _lookup(
        self, points: torch.Tensor, names: tuple[str, ...]
    ) -> tuple[list[torch.Tensor], torch.Tensor, torch.Tensor, torch.Tensor]:
        """The values of :meth:`forward`, their validity, and the trilinear weights ``(M, 8)``
        and value rows ``(M, 8)`` of the cells' corners (row 0 where a corner holds none)."""
        flat, w, inside = _cell_and_weights(points, self.origin, self.spacing, self.shape)
        rows = self.index.index_select(0, flat.view(-1)).view(flat.shape)  # (M, 8)
        # amin, not all: a bool reduction over a short last dimension is several times slower
        valid = (rows.amin(-1) >= 0) & inside
        rows = rows.clamp_min(0)
        values = [_interpolate(w, self.channel(n), rows) for n in names]
        return values, valid, w, rows
