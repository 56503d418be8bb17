"""Pose corpora: the body poses of many motions (BVH captures, USD body layers, AMASS ``.npz``)
in one file, so that the pose codec learns poses that the simulated training set lacks (a pose
needs no simulation; a garment target does).

A corpus file is an ``.npz`` with ``format`` (1), ``poses`` ``(M, 24, 3)`` float32 local
axis-angle rotations (rad, SMPL order), ``sources`` ``(S,)`` (the files' names), ``counts``
``(S,)`` (the poses each gave, in order) and ``fps`` (the rate the motions were sampled at).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from usd_garment.atomic import atomic_output
from usd_garment.body.joints import NUM_JOINTS
from usd_garment.body.model import BodyModel
from usd_garment.motion.bvh import DEFAULT_COLLARS
from usd_garment.motion.motion_file import read_motion_file
from usd_garment.motion.resample import resample_motion
from usd_garment.npz_file import read_npz

#: Version of the corpus file layout.
CORPUS_FORMAT = 1
#: The frame rate a corpus samples its motions at by default (poses 0.1 s apart: neighbours at
#: 120 or 30 fps add little but weight).
CORPUS_FPS = 10.0


@dataclass
class PoseCorpus:
    """Poses of several motions.

    Attributes:
        poses: ``(M, 24, 3)`` float32 local axis-angle rotations (rad), SMPL joint order.
        sources: each motion's file name.
        counts: the poses of each motion, in ``sources``' order (they sum to M).
        fps: the rate the motions were sampled at.
    """

    poses: np.ndarray
    sources: list[str]
    counts: list[int]
    fps: float


def build_pose_corpus(
    paths: Sequence[str | Path],
    body: BodyModel,
    fps: float = CORPUS_FPS,
    arm_clearance: float | None = None,
    collars: str = DEFAULT_COLLARS,
    progress: Callable[[Path], None] | None = None,
) -> PoseCorpus:
    """The poses of the motions in ``paths`` (see :func:`read_motion_file`; BVH captures with
    the arms as captured unless ``arm_clearance`` is given, ``collars`` as
    :func:`read_motion_file`'s), each resampled to ``fps``;
    ``progress`` is called with each file once read.

    Raises:
        ValueError: no paths, or ``fps`` not positive.
    """
    if not paths:
        raise ValueError("a pose corpus needs at least one motion file")
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    poses, sources, counts = [], [], []
    for path in map(Path, paths):
        motion = read_motion_file(path, body, arm_clearance=arm_clearance, collars=collars)
        pose = np.asarray(resample_motion(motion, fps).pose, dtype=np.float32)
        poses.append(pose)
        sources.append(path.name)
        counts.append(len(pose))
        if progress is not None:
            progress(path)
    return PoseCorpus(np.concatenate(poses), sources, counts, float(fps))


def save_pose_corpus(path: str | Path, corpus: PoseCorpus) -> None:
    """Write ``corpus`` as a compressed ``.npz``, atomically."""
    with atomic_output(Path(path)) as tmp, tmp.open("wb") as fh:
        np.savez_compressed(
            fh,
            format=np.array(CORPUS_FORMAT),
            poses=np.asarray(corpus.poses, dtype=np.float32),
            sources=np.array(corpus.sources),
            counts=np.array(corpus.counts, dtype=np.int64),
            fps=np.array(corpus.fps),
        )


def load_pose_corpus(path: str | Path) -> PoseCorpus:
    """Read a corpus written by :func:`save_pose_corpus`.

    Raises:
        ValueError: no such file, or not a pose corpus of this format.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such pose corpus file")
    data = read_npz(path, "not a readable pose corpus")
    keys = {"format", "poses", "sources", "counts", "fps"}
    if not keys <= data.keys() or int(data["format"]) != CORPUS_FORMAT:
        raise ValueError(f"{path}: not a pose corpus of format {CORPUS_FORMAT}")
    poses = np.asarray(data["poses"], dtype=np.float32)
    counts = [int(c) for c in data["counts"]]
    if poses.ndim != 3 or poses.shape[1:] != (NUM_JOINTS, 3) or sum(counts) != len(poses):
        raise ValueError(f"{path}: poses must be (M, 24, 3) with M the sum of counts")
    if not np.isfinite(poses).all():
        raise ValueError(f"{path}: the poses hold NaN or infinite values")
    return PoseCorpus(poses, [str(s) for s in data["sources"]], counts, float(data["fps"]))
