"""The common collision post-process of garment methods (the baselines, the learned method's
"+postprocess" variant, the simulator's end-of-frame projection): push garment vertices that are
inside the posed body (by winding number), or closer than ε to it, out along the body normal to ε
outside. Vertices whose closest body point lies itself inside the body (a limb pressed into the
trunk) have no outside to go to and stay where they are. In a crease narrower than 2ε (the gap
between a hanging arm and the trunk) a push out of one part lands in the other, so each later
pass halves ε: the vertex ends up between the two."""

from __future__ import annotations

import multiprocessing
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import AbstractContextManager, nullcontext
from types import TracebackType

import numpy as np
import torch

from usd_garment.eval.body_distance import BodyDistance, BodyFrames, BodySurface, signed_distance

#: Distance outside the body that pushed vertices are moved to (m); DESIGN.md, 2 mm.
PUSH_OUT_EPS = 2e-3
#: Passes of query-and-push; later passes only revisit vertices moved by the previous one, with
#: half the previous pass's distance (2, 1, 0.5, 0.25 mm).
PUSH_OUT_PASSES = 4


def push_out(
    points: np.ndarray,
    body_vertices: np.ndarray,
    surface: BodySurface,
    eps: float = PUSH_OUT_EPS,
    passes: int = PUSH_OUT_PASSES,
    first: BodyDistance | None = None,
    pool: PushOutPool | None = None,
) -> np.ndarray:
    """Move every point closer than ``eps`` to the body (or inside it) to ``eps`` outside,
    unless its closest body point lies inside another part of the body; pass k re-checks the
    moved points with ``eps / 2**k``.

    Args:
        points: ``(T, N, 3)`` posed garment points (m).
        body_vertices: ``(T, V, 3)`` posed body vertices (m) of the mesh ``surface`` describes.
        surface: the body's topology.
        eps: target distance outside the body (m) of the first pass.
        passes: how many times to re-check the moved points (a push can land a vertex inside
            another body part in a crease, e.g. out of the trunk into the arm).
        first: the query of ``points`` already made with ``probe_below=eps``, for the first
            pass (None: made here).
        pool: worker processes of the same body topology (:class:`PushOutPool`) that push
            blocks of frames in parallel; None: this process. The result is the same.

    Returns:
        ``(T, N, 3)`` pushed points, the input's dtype.
    """
    out = np.array(points, dtype=np.float64)
    blocks = [(a, min(a + BLOCK_FRAMES, len(out))) for a in range(0, len(out), BLOCK_FRAMES)]
    if pool is not None and first is None and len(blocks) > 1:
        pushed = pool.push_blocks(
            [out[a:b] for a, b in blocks], [body_vertices[a:b] for a, b in blocks], eps, passes
        )
        for (a, b), block in zip(blocks, pushed, strict=True):
            out[a:b] = block
    else:
        for a, b in blocks:
            frames = BodyFrames(body_vertices[a:b], surface)
            done = first.frames(a, b) if first is not None else None
            out[a:b] = _push_frames(out[a:b], frames, surface, eps, passes, done)
    return out.astype(np.asarray(points).dtype)


class PushOutPool:
    """Worker processes (one CPU core each, started once, "spawn") that run :func:`push_out` on
    blocks of frames of one body topology; use as a context manager, or :meth:`close` it.

    Args:
        surface: the body's topology, the same for every frame pushed with this pool.
        workers: processes.
    """

    def __init__(self, surface: BodySurface, workers: int) -> None:
        self.workers = workers
        self._executor = ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_start_worker,
            initargs=(surface.faces.numpy(), surface.num_vertices),
        )

    def push_blocks(
        self,
        points: list[np.ndarray],
        body_vertices: list[np.ndarray],
        eps: float,
        passes: int,
    ) -> Iterator[np.ndarray]:
        """:func:`push_out`'s passes on each block of frames, ``points[i]`` ``(t, N, 3)``
        float64 on ``body_vertices[i]`` ``(t, V, 3)``, in the workers; results in order."""
        count = len(points)
        return self._executor.map(
            _push_block, points, [np.asarray(v) for v in body_vertices], [eps] * count,
            [passes] * count,
        )  # fmt: skip

    def close(self) -> None:
        """Stop the workers."""
        self._executor.shutdown()

    def __enter__(self) -> PushOutPool:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()


def pool_for(
    surface: BodySurface | None, workers: int
) -> AbstractContextManager[PushOutPool | None]:
    """A :class:`PushOutPool` of ``workers`` processes for ``surface``, or None (as a context)
    when there is nothing to push (no surface) or one process does it (``workers`` ≤ 1)."""
    if surface is None or workers <= 1:
        return nullcontext(None)
    return PushOutPool(surface, workers)


#: The body topology of this worker process (:class:`PushOutPool`).
_WORKER_SURFACE: list[BodySurface] = []


def _start_worker(faces: np.ndarray, num_vertices: int) -> None:
    """Build the worker's body topology once; one thread (one core per worker)."""
    torch.set_num_threads(1)
    _WORKER_SURFACE.append(BodySurface(faces, num_vertices))


def _push_block(
    points: np.ndarray, body_vertices: np.ndarray, eps: float, passes: int
) -> np.ndarray:
    """:func:`push_out`'s passes on one block of frames ``(t, N, 3)`` float64, in a worker."""
    surface = _WORKER_SURFACE[0]
    frames = BodyFrames(body_vertices, surface)
    return _push_frames(points, frames, surface, eps, passes, None)


#: Frames whose search structures (:class:`BodyFrames`, about 10 MB each) are held at once,
#: built on first use and shared by every pass over those frames.
BLOCK_FRAMES = 16


def _push_frames(
    out: np.ndarray,
    frames: BodyFrames,
    surface: BodySurface,
    eps: float,
    passes: int,
    first: BodyDistance | None,
) -> np.ndarray:
    """The passes of :func:`push_out` on frames ``out`` ``(t, N, 3)`` float64, in place."""
    columns = np.arange(out.shape[1])
    for k in range(passes):
        if columns.size == 0:
            break
        step = eps / 2**k
        if k == 0 and first is not None:
            query = first
        else:
            query = signed_distance(
                out[:, columns], frames.vertices, surface, probe_below=step, frames=frames
            )
        near = (query.distance < step) & ~query.closest_inside  # (t, C)
        if not near.any():
            break
        pushed = query.closest + step * query.normal
        sub = out[:, columns]
        sub[near] = pushed[near]
        out[:, columns] = sub
        columns = columns[near.any(axis=0)]
    return out
