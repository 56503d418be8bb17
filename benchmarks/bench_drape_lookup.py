"""Where the information for a garment's drape is: a k-nearest-neighbour lookup over a canonical
set's training frames predicts each validation and test frame's canonical garment as the mean of
the k training frames nearest in a choice of features (joint rotations, or a trained model's
pose code), each with 0.3 × β₁..β₄. Its error (mm, mean vertex distance in the canonical space)
per held-out sequence says which features carry what the garment depends on; compare it with
the networks' error of ``usd-garment dataset floor --model``.

On the dress, validation / test: 22.3 / 22.6 mm on the hips, knees and spine (3–4 mm on the slow
arm raises), 30.5 / 28.7 mm on all joints; on member 0's 10-d pose code 27.4 / 30.3 mm uniform,
26.8 / 27.2 weighted by the garment with floor 0.1 (stop 30), 25.8 / 27.0 with floor 0 (stop 31).

Run: ``python benchmarks/bench_drape_lookup.py scratch/canonical_dress_v4.npz
[--run scratch/runs/dress_v4_m0 ...] [--k 5]``
"""

from __future__ import annotations

import argparse

import numpy as np
import torch
from scipy.spatial import cKDTree

from usd_garment.canonical.dataset import CanonicalSet, load_canonical_set
from usd_garment.training.pipeline import load_stage
from usd_garment.training.vae import split_frames

#: SMPL joints of the raw-rotation features: hips, knees and spine; all but the hands.
JOINT_SETS = {"hips, knees, spine": [1, 2, 3, 4, 5, 6, 9], "joints 1-21": list(range(1, 22))}
#: Weight of β₁..β₄ beside the features (rad).
BETA_WEIGHT = 0.3


def lookup_errors(data: CanonicalSet, features: np.ndarray, k: int) -> list[tuple[int, float]]:
    """Per validation and test sequence of ``data``, (index, mean vertex error in mm) of the k-NN
    lookup over its training frames in ``features`` ``(M, D)`` (one row per frame)."""
    train = split_frames(data, "train")
    tree = cKDTree(features[train])
    targets = np.asarray(data.canonical)[train]  # (M_train, N, 3), m
    out = []
    for index in data.split_sequences("validation") + data.split_sequences("test"):
        frames = data.sequence(index)
        _, nearest = tree.query(features[frames], k=k)
        error = np.linalg.norm(data.canonical[frames] - targets[nearest].mean(axis=1), axis=-1)
        out.append((index, 1e3 * float(error.mean())))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("canonical", help="a canonical set (.npz)")
    parser.add_argument("--run", action="append", default=[], help="a run folder's pose code")
    parser.add_argument("--k", type=int, default=5)
    args = parser.parse_args()
    data = load_canonical_set(args.canonical)
    pose = np.asarray(data.pose, dtype=np.float32)
    sequence = np.repeat(np.arange(len(data.splits)), np.diff(data.frame_offsets))
    betas = BETA_WEIGHT * np.asarray(data.betas)[sequence, :4]
    features = {name: pose[:, joints].reshape(len(pose), -1) for name, joints in JOINT_SETS.items()}
    spread = float(features["joints 1-21"].std())
    for run in args.run:
        codec = load_stage(run, "pose")[0]
        with torch.no_grad():
            code = codec.encode(torch.as_tensor(pose)).numpy()
        features[f"pose code of {run}"] = code / code.std(axis=0).mean() * spread
    names = ["_".join(str(s).rsplit("/", 1)[-1].split("_")[:2]) for s in data.sources]
    for label, values in features.items():
        rows = dict(lookup_errors(data, np.concatenate([values, betas], axis=1), args.k))
        means = []
        for split in ("validation", "test"):
            indices = data.split_sequences(split)
            frames = np.diff(data.frame_offsets)[indices]
            mean = np.average([rows[i] for i in indices], weights=frames)
            means.append(f"{split} {mean:.2f} mm")
        details = " | ".join(f"{names[i]} {e:.1f}" for i, e in rows.items())
        print(f"{label}: {', '.join(means)} | {details}")


if __name__ == "__main__":
    main()
