"""The canonical training set file: projected garment sequences, one ``.npz``.

Arrays (S sequences, T = ΣT_s frames in all, N garment vertices, F triangles):
    canonical ``(T, N, 3)`` float32: canonical garment X per frame (m), sequences one after
        another; sequence s is frames ``frame_offsets[s] .. frame_offsets[s+1]−1``.
    frame_offsets ``(S + 1,)`` int64.
    betas ``(S, 10)``, pose ``(T, 24, 3)`` (rad), trans ``(T, 3)`` (m), fps ``(S,)``: float32.
    error ``(T,)``, max_error ``(T,)`` float32: mean and largest reprojection distance (m).
    template ``(N, 3)`` float32 and faces ``(F, 3)`` int32: the garment template.
    sources ``(S,)`` str: the simulated layer each sequence came from.
    splits ``(S,)`` str: the split of each sequence ("train", "validation" or "test").
    metadata: a JSON string (garment, lod, body model, projection settings, package version).
    flagged ``(T,)`` bool: frames the simulation kept although they failed its checks (the
        garment layer's ``per_frame.bad``); absent from sets projected before it was recorded.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from usd_garment.atomic import atomic_output
from usd_garment.motion.sequence import SmplMotion

_ARRAYS = ("canonical", "frame_offsets", "betas", "pose", "trans", "fps", "error", "max_error")


@dataclass
class CanonicalSet:
    """The content of a canonical training set file (see the module docstring for shapes)."""

    canonical: np.ndarray
    frame_offsets: np.ndarray
    betas: np.ndarray
    pose: np.ndarray
    trans: np.ndarray
    fps: np.ndarray
    error: np.ndarray
    max_error: np.ndarray
    template: np.ndarray
    faces: np.ndarray
    sources: list[str] = field(default_factory=list)
    splits: list[str] = field(default_factory=list)
    metadata: dict[str, Any] = field(default_factory=dict)
    flagged: np.ndarray | None = None

    @property
    def num_sequences(self) -> int:
        return len(self.frame_offsets) - 1

    def sequence(self, s: int) -> slice:
        """Frames of sequence ``s`` as a slice into the per-frame arrays."""
        return slice(int(self.frame_offsets[s]), int(self.frame_offsets[s + 1]))

    def motion(self, s: int) -> SmplMotion:
        """The body motion of sequence ``s``: its betas ``(10,)``, pose ``(T_s, 24, 3)`` and
        trans ``(T_s, 3)`` as float32, at its fps."""
        frames = self.sequence(s)
        return SmplMotion(
            betas=np.asarray(self.betas[s], dtype=np.float32),
            pose=np.asarray(self.pose[frames], dtype=np.float32),
            trans=np.asarray(self.trans[frames], dtype=np.float32),
            fps=float(self.fps[s]),
        )

    def split_sequences(self, split: str) -> list[int]:
        """Indices of the sequences in ``split``."""
        return [s for s, name in enumerate(self.splits) if name == split]

    def flags(self) -> np.ndarray:
        """``(T,)`` bool: the frames the simulation flagged (see :attr:`flagged`).

        Raises:
            ValueError: the set has no record of them (projected before it was kept).
        """
        if self.flagged is None:
            raise ValueError(
                "the canonical set has no record of the frames the simulation flagged (it was "
                "projected before that was kept): project its layers again"
            )
        return np.asarray(self.flagged, dtype=bool)


def concat_canonical_sets(first: CanonicalSet, second: CanonicalSet) -> CanonicalSet:
    """The sequences of ``first`` then those of ``second``, with ``second``'s metadata.

    Raises:
        ValueError: the two sets are of different garment meshes.
    """
    if not (
        np.array_equal(first.faces, second.faces)
        and np.allclose(first.template, second.template, atol=1e-6)
    ):
        raise ValueError("the two canonical sets are of different garment templates")
    per_frame = {
        name: np.concatenate([getattr(first, name), getattr(second, name)])
        for name in ("canonical", "pose", "trans", "error", "max_error")
    }
    return CanonicalSet(
        **per_frame,
        frame_offsets=np.concatenate(
            [first.frame_offsets, first.frame_offsets[-1] + second.frame_offsets[1:]]
        ),
        betas=np.concatenate([first.betas, second.betas]),
        fps=np.concatenate([first.fps, second.fps]),
        template=second.template,
        faces=second.faces,
        sources=[*first.sources, *second.sources],
        splits=[*first.splits, *second.splits],
        metadata=second.metadata,
        flagged=None
        if first.flagged is None or second.flagged is None
        else np.concatenate([first.flagged, second.flagged]),
    )


def save_canonical_set(path: str | Path, data: CanonicalSet) -> None:
    """Write ``data`` to ``path`` atomically (``.npz``)."""
    arrays = {name: getattr(data, name) for name in _ARRAYS}
    flags = {} if data.flagged is None else {"flagged": np.asarray(data.flagged, dtype=bool)}
    with atomic_output(path) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(
            handle,
            **{k: np.asarray(v, dtype=np.int64 if k == "frame_offsets" else np.float32)
               for k, v in arrays.items()},
            template=np.asarray(data.template, dtype=np.float32),
            faces=np.asarray(data.faces, dtype=np.int32),
            sources=np.array(data.sources, dtype=str),
            splits=np.array(data.splits, dtype=str),
            metadata=np.array(json.dumps(data.metadata)),
            **flags,
        )  # fmt: skip


def load_canonical_set(path: str | Path) -> CanonicalSet:
    """Read a canonical training set file.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a canonical training set file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with np.load(path) as npz:
            values = {name: npz[name] for name in (*_ARRAYS, "template", "faces")}
            sources = [str(s) for s in npz["sources"]]
            splits = [str(s) for s in npz["splits"]]
            metadata = json.loads(str(npz["metadata"]))
            flagged = npz["flagged"] if "flagged" in npz.files else None
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a canonical training set file ({exc})") from exc
    return CanonicalSet(
        **values, sources=sources, splits=splits, metadata=metadata, flagged=flagged
    )
