"""A motion capture as parsed, before retargeting: a BVH-style skeleton (joints in file order,
OFFSETs, Euler channels) and its channel values per frame. BVH files are parsed into it
(:mod:`usd_garment.motion.bvh`), and so are ASF/AMC captures (:mod:`usd_garment.motion.asf_amc`),
so that both retarget the same way."""

from __future__ import annotations

import gzip
import lzma
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np


class BvhError(ValueError):
    """A capture (BVH, or ASF/AMC) that cannot be read or retargeted."""


@dataclass
class BvhSkeleton:
    """The HIERARCHY of a BVH file (or an ASF skeleton laid out as one), joints in file
    (depth-first) order, parents first.

    Attributes:
        names: ``J`` joint names as written (``mixamorig:Hips``).
        parents: ``(J,)`` parent index, −1 for the root.
        offsets: ``(J, 3)`` OFFSET of each joint from its parent (file units).
        channels: per joint, its channel names as written (``Zrotation``, ``Xposition`` ...).
        end_sites: ``(J, 3)`` OFFSET of each joint's End Site (file units), NaN where none.
    """

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    channels: list[tuple[str, ...]]
    end_sites: np.ndarray

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def children(self, joint: int) -> list[int]:
        """Indices of the joints whose parent is ``joint``."""
        return [int(i) for i in np.flatnonzero(self.parents == joint)]

    def path(self, ancestor: int, joint: int) -> list[int] | None:
        """Joints from ``ancestor`` down to ``joint``, both included; None if not below it."""
        chain = [joint]
        while chain[-1] != ancestor:
            parent = int(self.parents[chain[-1]])
            if parent < 0:
                return None
            chain.append(parent)
        return chain[::-1]


@dataclass
class BvhClip:
    """A parsed capture: a BVH file, or an ASF/AMC pair laid out as one (``asf_amc``).

    Attributes:
        skeleton: the HIERARCHY.
        values: ``(T, C)`` float64 channel values per frame, in the file's channel order
            (positions in file units, rotations in degrees).
        frame_time: seconds per frame.
    """

    skeleton: BvhSkeleton
    values: np.ndarray
    frame_time: float

    @property
    def num_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def fps(self) -> float:
        """Frames per second, rounded to a whole number when within 0.05 of one (0.008333 s)."""
        rate = 1.0 / self.frame_time
        return float(round(rate)) if abs(rate - round(rate)) < 0.05 else rate


#: A compressed format: its name, its reader and the errors that a broken file raises.
Compression = tuple[str, Callable[..., IO[bytes]], tuple[type[Exception], ...]]
#: Compressed capture files :func:`read_text` opens, by their last suffix (``walk.bvh.xz``).
COMPRESSED_SUFFIXES: dict[str, Compression] = {
    ".xz": ("xz", lzma.open, (lzma.LZMAError, EOFError)),
    ".gz": ("gzip", gzip.open, (gzip.BadGzipFile, zlib.error, EOFError)),
}


def has_suffix(path: str | Path, suffix: str) -> bool:
    """Whether ``path``'s name ends in ``suffix`` (``".bvh"``), or in it and then ``.xz`` or
    ``.gz``; any case."""
    suffixes = [s.lower() for s in Path(path).suffixes]
    if suffixes and suffixes[-1] in COMPRESSED_SUFFIXES:
        suffixes = suffixes[:-1]
    return bool(suffixes) and suffixes[-1] == suffix


def read_text(path: str | Path, kind: str) -> str:
    """The text of the capture file at ``path`` (a ``kind`` file, e.g. ``"BVH"``, for the error
    messages), xz- or gzip-compressed where its name ends in ``.xz`` or ``.gz``.

    Raises:
        BvhError: a broken compressed file, or one that is not text.
        OSError: the file cannot be read.
    """
    path = Path(path)
    compression = COMPRESSED_SUFFIXES.get(path.suffix.lower())
    if compression is not None:
        name, opener, errors = compression
        try:
            with opener(path, "rb") as stream:
                data = stream.read()
        except errors as exc:
            raise BvhError(f"{path}: not a valid {name}-compressed file ({exc})") from None
    else:
        data = path.read_bytes()
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise BvhError(f"{path}: not a {kind} file (not text)") from None


def parse_floats(words: Sequence[str], where: str) -> np.ndarray:
    """``words`` as finite float64 numbers ``(len(words),)``; ``where`` (``file:line``) prefixes
    the error.

    Raises:
        BvhError: a word that is not a number, or NaN or infinity.
    """
    try:
        vec = np.asarray([float(w) for w in words], dtype=np.float64)
    except ValueError:
        raise BvhError(f"{where}: expected numbers") from None
    if not np.isfinite(vec).all():
        raise BvhError(f"{where}: NaN or infinite value")
    return vec
