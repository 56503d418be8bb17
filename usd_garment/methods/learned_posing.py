"""The learned method's canonical garments posed by the garment model M_G and pushed out of the
parts posing carries them into (``learned+preimage``), a chunk of frames at a time: in this
process, or in forked worker processes while this one decodes the next chunks and writes the
last ones (``dress --workers``).

Posing and the preimage push are most of ``learned+preimage``'s time and long chains of small
tensor operations: on two cores two torch threads run them about 1.4 times as fast as one,
while two processes of one thread each run twice as much. Forked workers share the caller's
body fields and garment model without copying them, and pose and push exactly as this process
would at one thread: the garment is the same to the bit (at two threads a matrix product's
rows are split between them and may round otherwise: up to 3e-7 m, stop 89). A platform that
cannot fork has no workers.

Shapes: t frames of a chunk, N garment vertices, J = 24 joints, K = 10 shape coefficients.
Units: metres.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
import torch

from usd_garment.body.lbs import unskin_blended
from usd_garment.canonical.preimage_push import PartBoxes, preimage_push
from usd_garment.canonical.push_out import LIPSCHITZ, push_out_canonical
from usd_garment.canonical.shape_gap import ShapeGap
from usd_garment.fields.body_fields import FieldTangent
from usd_garment.garment.model import Articulation, GarmentModel
from usd_garment.motion.cuts import smooth_runs
from usd_garment.motion.jumps import RootJump, jump_maps, mapped

#: Frames posed at once within a chunk (bounds memory: ~N·(3 + 24 + 30) floats per frame).
POSE_FRAMES = 64

#: Consecutive frames of a chunk ``(start, stop)`` and the fields to first order they are posed
#: with (None: looked up exactly).
Part = tuple[slice, FieldTangent | None]


#: A chunk posed by :func:`pose_chunk`: the posed garment ``(t, N, 3)`` (m), the points before
#: skinning ``(t, N, 3)`` (m) and, where asked for, the blended skinning transforms of its
#: pieces of :data:`POSE_FRAMES` frames or fewer, in order (each ``(p, N, 3, 4)``).
Posed = tuple[torch.Tensor, torch.Tensor, list[torch.Tensor] | None]


def pose_chunk(
    garment_model: GarmentModel,
    x: torch.Tensor,
    parts: Sequence[Part],
    art: Articulation,
    blended: bool = False,
) -> Posed:
    """The canonical garments ``x`` ``(t, N, 3)`` (m) of a chunk posed, each part of its frames
    with its tangent and :data:`POSE_FRAMES` frames at a time: the garment, the points before
    skinning (``GarmentOutput.unposed``) and, if asked for, the pieces' blended transforms
    (``GarmentOutput.blended``; else None). Those are left in pieces: a chunk's together would
    take a fresh allocation of about 55 MB, and its page faults cost more than the rest of
    the posed smoothing's inverse skinning. Each piece's weights ``(p, N, J)`` are dropped as
    it is posed (27 MB a piece of 64 frames; kept to the chunk's end they put the streamed
    peak of the T-shirt's version 9 over 1 GB)."""
    vertices: list[torch.Tensor] = []
    unposed: list[torch.Tensor] = []
    pieces: list[torch.Tensor] = []
    for frames, tangent in parts:
        for a in range(frames.start, frames.stop, POSE_FRAMES):
            b = slice(a, min(a + POSE_FRAMES, frames.stop))
            out = garment_model.pose(x[b], art[b], tangent)  # its weights dropped here
            vertices.append(out.vertices)
            unposed.append(out.unposed)
            if blended:
                pieces.append(out.blended)
    return torch.cat(vertices), torch.cat(unposed), pieces if blended else None


#: The Gaussian of :class:`Smoothing` reaches this many standard deviations (scipy's default).
TRUNCATE = 4.0


@dataclass(frozen=True)
class Smoothing:
    """A Gaussian of ``sigma`` frames over the frames of a posed garment (``LearnedModel``'s
    ``posed_smoothing`` at the input's frame rate; 0: none), the nearest frame repeated beyond
    the motion's ends and on each side of its ``cuts`` (the frames where another motion starts,
    :func:`~usd_garment.motion.cuts.motion_restarts`). Across each of its ``jumps`` (a jump of
    the root alone, a teleport or a heading snapped) the Gaussian goes on, the jump taken out
    of the frames after it while they are smoothed and put back after: the frames straight
    across a teleport would carry the garment a frame off the body, and repeating the nearest
    frame there would hold it back a step. A chunk of frames is smoothed as the whole motion
    would be where it is posed with :attr:`radius` frames of the motion on each side (fewer at
    its ends), with the cuts and jumps :meth:`within` it."""

    sigma: float = 0.0
    cuts: tuple[int, ...] = ()
    jumps: tuple[RootJump, ...] = ()

    @classmethod
    def of(
        cls, seconds: float, fps: float, cuts: Sequence[int] = (), jumps: Sequence[RootJump] = ()
    ) -> Smoothing:
        """The smoothing of ``seconds`` (standard deviation) at ``fps`` frames a second."""
        return cls(seconds * fps, tuple(cuts), tuple(jumps))

    @property
    def radius(self) -> int:
        """Frames of the motion the Gaussian reaches on each side of a frame."""
        return int(TRUNCATE * self.sigma + 0.5) if self.sigma > 0 else 0

    def within(self, start: int, stop: int) -> Smoothing:
        """This smoothing of the frames ``start`` to ``stop`` of the motion: the cuts and jumps
        among them, counted from ``start``."""
        return Smoothing(
            self.sigma,
            tuple(k - start for k in self.cuts if start < k < stop),
            tuple(RootJump(j.frame - start, j.undo) for j in self.jumps if start < j.frame < stop),
        )

    def apply(
        self,
        x: torch.Tensor,
        posed: Posed,
        core: slice,
        sdf: Callable[[torch.Tensor], torch.Tensor] | None,
        floor: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The posed garment ``(c, N, 3)`` of the frames ``core`` (c of them) of a chunk and
        the frames of the motion around it, ``posed`` from the canonical garments ``x``
        ``(t, N, 3)`` (:func:`pose_chunk`'s, with the blended transforms where :attr:`sigma`
        > 0), smoothed, and the points before skinning ``(c, N, 3)`` that skin to it.

        With the canonical body's ``sdf``, a smoothed vertex cannot end inside its own body
        part: the mean of a vertex's positions over neighbouring frames lies inside the curve
        it follows, and a fast limb's sleeve is carried into the limb, where the preimage push
        (which leaves each vertex's own preimage out of its search) would not find it. So each
        smoothed vertex's own preimage is found again, to first order (one inverse skinning by
        its blended transform), pushed ε out of the canonical body where it is less (as the
        decoded garment was: :func:`push_out_canonical`), and the vertex moved with it. With
        ``floor`` ``(t, N)``, a lower bound on the SDF of ``x`` (m; :func:`push_out_canonical`
        returns one), only the own preimages that this bound, less how far they are from
        ``x``, leaves near the body are looked up (about a third on a walk)."""
        points, before, pieces = posed
        if self.sigma <= 0:
            return points[core], before[core]
        assert pieces is not None, "pose_chunk(..., blended=True) for a smoothing"
        smoothed = torch.from_numpy(self._smoothed(points.numpy()))
        out: list[tuple[torch.Tensor, torch.Tensor]] = []
        start = 0
        for blended in pieces:  # the core's frames piece by piece
            stop = start + len(blended)
            a, b = max(start, core.start), min(stop, core.stop)
            if a < b:
                frames = slice(a, b)
                out.append(_own_preimages(
                    smoothed[frames], blended[a - start : b - start], before[frames], x[frames],
                    sdf, None if floor is None else floor[frames],
                ))  # fmt: skip
            start = stop
        return torch.cat([v for v, _ in out]), torch.cat([u for _, u in out])

    def _smoothed(self, points: np.ndarray) -> np.ndarray:
        """The posed garment ``(t, N, 3)`` float32 (m) smoothed: each run between the cuts on
        its own, with the jumps taken out while it is (:func:`jump_maps`)."""
        if not self.jumps:
            return smooth_runs(points, self.sigma, self.cuts, truncate=TRUNCATE)
        maps = jump_maps(len(points), self.jumps)
        moved = mapped(maps, points)
        smoothed = smooth_runs(moved, self.sigma, self.cuts, truncate=TRUNCATE)
        start = self.jumps[0].frame  # the frames before the first jump were not moved
        smoothed[start:] = mapped(np.linalg.inv(maps[start:]), smoothed[start:])
        return smoothed.astype(np.float32)


def _own_preimages(
    vertices: torch.Tensor,
    blended: torch.Tensor,
    before: torch.Tensor,
    x: torch.Tensor,
    sdf: Callable[[torch.Tensor], torch.Tensor] | None,
    floor: torch.Tensor | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Smoothed vertices ``(p, N, 3)`` (m) of p frames, with their blended transforms
    ``(p, N, 3, 4)``, and the points before skinning ``(p, N, 3)`` that skin to them; with the
    canonical body's ``sdf``, those whose own preimage is within ε of the body moved out with
    it (:meth:`Smoothing.apply`). ``x`` ``(p, N, 3)``: the canonical garments posed, to the
    points ``before`` ``(p, N, 3)`` skinning; ``floor`` ``(p, N)``: a lower bound on their SDF
    (m), or None."""
    unposed = unskin_blended(vertices, blended)  # (p, N, 3): shaped rest frame
    if sdf is None:
        return vertices, unposed
    canonical = unposed - (before - x)  # less the shape offsets B̃s(X)·β
    if floor is not None:
        floor = floor - LIPSCHITZ * (canonical - x).norm(dim=-1)
    move = push_out_canonical(canonical, sdf, floor=floor)[0] - canonical  # zero for most
    frame, vertex = move.any(-1).nonzero(as_tuple=True)  # the few moved
    step = move[frame, vertex]
    vertices[frame, vertex] += torch.einsum("mab,mb->ma", blended[frame, vertex, :, :3], step)
    unposed[frame, vertex] += step
    return vertices, unposed


def available_cores() -> int:
    """The CPU cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def can_fork() -> bool:
    """Whether this platform starts worker processes by forking (Linux does)."""
    return "fork" in multiprocessing.get_all_start_methods()


@dataclass(frozen=True)
class _Work:
    """What every chunk of one motion shares: the garment model (with the body's fields), the
    body shape ``(K,)``, the body parts' boxes, the push's distance ε (m) and the shape fields'
    shortfall on that body (``shape_gap``; None for the template shape)."""

    garment_model: GarmentModel
    betas: torch.Tensor
    boxes: PartBoxes
    epsilon: float
    gap: ShapeGap | None


#: A worker's work, set when it starts (:func:`_start`).
_WORK: list[_Work] = []

#: A part of a chunk as sent to a worker: its frames and its tangent's tensors (anchor, value,
#: derivative), channel sizes and radius, or None.
_PartState = tuple[int, int, tuple[np.ndarray, np.ndarray, np.ndarray, list[int], float] | None]


def _start(work: _Work) -> None:
    """A worker's start: one torch thread, and the work it inherited from the fork (the
    arguments of a forked process are not pickled)."""
    torch.set_num_threads(1)
    _WORK[:] = [work]


def _pose_and_push(
    x: np.ndarray,
    floor: np.ndarray | None,
    parts: list[_PartState],
    pose: np.ndarray,
    trans: np.ndarray,
    core: slice,
    smoothing: Smoothing,
) -> np.ndarray:
    """One chunk in a worker: posed (:func:`pose_chunk`), its frames ``core`` smoothed, then
    :func:`preimage_push`."""
    work = _WORK[0]
    fields = work.garment_model.fields
    tangents = [
        (slice(a, b), None if s is None else FieldTangent(fields, *map(_tensor, s[:3]), *s[3:]))
        for a, b, s in parts
    ]
    with torch.no_grad():
        art = work.garment_model.articulation(work.betas, _tensor(pose), _tensor(trans))
        canonical = _tensor(x)
        posed = pose_chunk(work.garment_model, canonical, tangents, art, smoothing.sigma > 0)
        vertices, unposed = smoothing.apply(
            canonical, posed, core, fields.sdf,
            None if floor is None else _tensor(floor),
        )  # fmt: skip
        del posed  # freed before the push (the blended transforms: ~55 MB a chunk)
        pushed = preimage_push(
            vertices, unposed, art.transforms[core], fields, work.betas, work.boxes,
            work.epsilon, work.gap,
        )  # fmt: skip
    return pushed.numpy()


def _tensor(array: np.ndarray) -> torch.Tensor:
    """The tensor that shares ``array``'s memory."""
    return torch.from_numpy(array)


class PosingPool:
    """``workers`` forked processes of one torch thread each that pose chunks of one motion's
    canonical garment and push them out (:func:`pose_chunk`, then :func:`preimage_push`), until
    :meth:`close`. The processes start at the first :meth:`submit` and inherit the garment
    model and the rest of :class:`_Work` from the fork.

    Raises:
        ValueError: the platform cannot fork (:func:`can_fork`; ``multiprocessing``'s own
            error).
    """

    def __init__(
        self,
        workers: int,
        garment_model: GarmentModel,
        betas: torch.Tensor,
        boxes: PartBoxes,
        epsilon: float,
        gap: ShapeGap | None = None,
    ) -> None:
        self.workers = workers
        self._executor = ProcessPoolExecutor(
            workers, mp_context=multiprocessing.get_context("fork"), initializer=_start,
            initargs=(_Work(garment_model, betas, boxes, epsilon, gap),),
        )  # fmt: skip

    def submit(
        self,
        x: torch.Tensor,
        floor: torch.Tensor | None,
        parts: Sequence[Part],
        pose: torch.Tensor,
        trans: torch.Tensor,
        core: slice,
        smoothing: Smoothing,
    ) -> Future[np.ndarray]:
        """The posed and pushed garment ``(c, N, 3)`` float32 (m) of the frames ``core`` (c of
        them) of the canonical garments ``x`` ``(t, N, 3)`` posed by ``pose`` ``(t, J, 3)``
        (rad) and ``trans`` ``(t, 3)`` (m), each part of the frames with its tangent, and
        smoothed, to come. ``floor``: a lower bound ``(t, N)`` on the SDF of ``x`` or None
        (:meth:`Smoothing.apply`'s; sent only where there is a smoothing)."""
        states: list[_PartState] = [
            (frames.start, frames.stop, None if t is None else (
                t.anchor.numpy(), t.value.numpy(), t.derivative.numpy(), t.sizes, t.radius,
            ))
            for frames, t in parts
        ]  # fmt: skip
        return self._executor.submit(
            _pose_and_push, x.numpy(),
            floor.numpy() if floor is not None and smoothing.sigma > 0 else None, states,
            pose.numpy(), trans.numpy(), core, smoothing,
        )  # fmt: skip

    def close(self) -> None:
        """Stop the workers, dropping the chunks not started."""
        self._executor.shutdown(cancel_futures=True)
