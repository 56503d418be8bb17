"""The common collision post-process of garment methods (the baselines, the learned method's
"+postprocess" variant, the simulator's end-of-frame projection): push garment vertices that are
inside the posed body (by winding number), or closer than ε to it, out along the body normal to ε
outside. Vertices whose closest body point lies itself inside the body (a limb pressed into the
trunk) have no outside to go to and stay where they are. In a crease narrower than 2ε (the gap
between a hanging arm and the trunk) a push out of one part lands in the other, so each later
pass halves ε: the vertex ends up between the two."""

from __future__ import annotations

import numpy as np

from usd_garment.eval.body_distance import (
    BodyDistance,
    BodyFrames,
    BodyPool,
    BodySurface,
    signed_distance,
    worker_surface,
)

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
    pool: BodyPool | None = None,
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
        pool: worker processes (:class:`BodyPool`) that push blocks of frames in parallel;
            None: this process. The result is the same.

    Returns:
        ``(T, N, 3)`` pushed points, the input's dtype.
    """
    out = np.array(points, dtype=np.float64)
    blocks = [(a, min(a + BLOCK_FRAMES, len(out))) for a in range(0, len(out), BLOCK_FRAMES)]
    if pool is not None and first is None and len(blocks) > 1:
        count = len(blocks)
        pushed = pool.map(
            _push_block, [out[a:b] for a, b in blocks],
            [np.asarray(body_vertices[a:b]) for a, b in blocks], [surface.faces.numpy()] * count,
            [eps] * count, [passes] * count,
        )  # fmt: skip
        for (a, b), block in zip(blocks, pushed, strict=True):
            out[a:b] = block
    else:
        for a, b in blocks:
            frames = BodyFrames(body_vertices[a:b], surface)
            done = first.frames(a, b) if first is not None else None
            out[a:b] = _push_frames(out[a:b], frames, surface, eps, passes, done)
    return out.astype(np.asarray(points).dtype)


def _push_block(
    points: np.ndarray, body_vertices: np.ndarray, faces: np.ndarray, eps: float, passes: int
) -> np.ndarray:
    """:func:`push_out`'s passes on one block of frames ``(t, N, 3)`` float64, in a worker of
    a :class:`BodyPool`."""
    surface = worker_surface(faces, body_vertices.shape[1])
    return _push_frames(points, BodyFrames(body_vertices, surface), surface, eps, passes, None)


#: Frames whose search structures (:class:`BodyFrames`, a few MB each) are held at once,
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
