"""Contact sheet of BVH motion captures retargeted to SMPL: a few frames of each clip on the
default body, with the BVH skeleton drawn over it (black lines, dots at the mapped joints); the
shoulders are opened where the arms would pass through the trunk and the collars turn from the
rest (``load_bvh``'s defaults).

Run: ``python examples/plot_bvh.py [-o docs/mocap.png] [FILE.bvh|FILE.amc ...]`` (default: CMU
clips 131_01 and 131_03 from ``/work/shared/mocap``); ``docs/mocap_amc.png``:
``python examples/plot_bvh.py -o docs/mocap_amc.png examples/mocap/asf/02_05.amc.xz
examples/mocap/asf/02_10.amc.xz``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch

from usd_garment.body import load_body_model
from usd_garment.eval.render import SKIN, draw_meshes, view_axes
from usd_garment.motion.bvh import load_bvh, map_joints, read_capture, up_rotation, world_motion

MOCAP = Path("/work/shared/mocap")
CLIPS = (MOCAP / "cmu_131_01.bvh", MOCAP / "cmu_131_03.bvh")
FPS = 30.0
COLUMNS = 8
VIEWS = (("front-left 40°", 40.0), ("left side 90°, +Z ←", 90.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("clips", nargs="*", type=Path, default=list(CLIPS))
    parser.add_argument("-o", "--output", type=Path, default=Path("docs/mocap.png"))
    args = parser.parse_args()

    body = load_body_model()
    faces = body.faces.numpy()
    rows = [(clip, view) for clip in args.clips for view in VIEWS]
    fig, axes = plt.subplots(
        len(rows), COLUMNS, squeeze=False, figsize=(1.7 * COLUMNS, 2.5 * len(rows))
    )
    for row, (path, (view_name, view_deg)) in enumerate(rows):
        motion, info = load_bvh(path, body, fps=FPS)
        clip = read_capture(path)
        mapping = map_joints(clip.skeleton)
        frames = np.linspace(0, motion.num_frames - 1, COLUMNS).round().astype(int)
        source = np.minimum(
            (frames * info.source_fps / FPS).round().astype(int), clip.num_frames - 1
        )
        _, bvh_pos, _ = world_motion(clip, info.scale, up_rotation(info.up_axis), source)
        bvh_pos[..., 1] += info.floor_shift_m
        with torch.no_grad():
            out = body(
                torch.as_tensor(motion.betas),
                torch.as_tensor(motion.pose[frames]),
                torch.as_tensor(motion.trans[frames]),
            )
        right, _ = view_axes(view_deg)
        parents = clip.skeleton.parents
        for col, frame in enumerate(frames):
            ax = axes[row, col]
            centre = motion.trans[frame].astype(np.float64) * [1.0, 0.0, 1.0]
            v = out.vertices[col].double().numpy() - centre  # keep the walker in frame
            draw_meshes(ax, [(v, faces, SKIN)], view_deg)
            p = bvh_pos[col] - centre
            for j, parent in enumerate(parents):
                if parent >= 0:
                    seg = p[[parent, j]]
                    ax.plot(seg @ right, seg[:, 1], color="k", lw=0.6, alpha=0.8)
            mapped = p[[m for m in mapping if m is not None]]
            ax.plot(mapped @ right, mapped[:, 1], "o", color="k", ms=1.2)
            ax.axhline(0.0, color="0.5", lw=0.6)
            ax.set_xlim(-0.9, 0.9)
            ax.set_ylim(-0.1, 1.9)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            x, _, z = motion.trans[frame]
            ax.set_title(f"t={frame / FPS:.1f}s x={x:+.2f} z={z:+.2f}", fontsize=6)
            if col == 0:
                ax.set_ylabel(f"{path.stem}\n{view_name}", fontsize=8)
    fig.suptitle(
        "BVH captures retargeted to SMPL (default body, shoulders opened where an arm would pass "
        "through the trunk); black: the BVH skeleton in its own proportions, same hips; "
        "grey: floor y=0",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=90)


if __name__ == "__main__":
    main()
