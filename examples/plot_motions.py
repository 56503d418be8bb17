"""Contact sheet of the procedural motions: a few frames of each kind on the default body, seen
from the front-left at 40°, drawn as flat-shaded triangles (painter's algorithm).

Run: ``python examples/plot_motions.py [-o docs/motions.png] [--seed 0] [--kinds walk ...]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import torch

from usd_garment.body import load_body_model
from usd_garment.eval.render import SKIN, draw_meshes
from usd_garment.motion.procedural import MOTION_KINDS, make_motion

FPS = 30.0
FRAMES = 96
SHOWN = (0, 15, 30, 45, 60, 75, 95)
VIEW_DEG = 40.0  # view turned from the front towards the body's left


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("docs/motions.png"))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--kinds", nargs="+", choices=list(MOTION_KINDS), default=list(MOTION_KINDS)
    )
    args = parser.parse_args()

    body = load_body_model()
    faces = body.faces.numpy()
    kinds = args.kinds
    fig, axes = plt.subplots(
        len(kinds), len(SHOWN), squeeze=False, figsize=(2.0 * len(SHOWN), 2.3 * len(kinds))
    )
    for row, kind in enumerate(kinds):
        motion = make_motion(kind, FRAMES, FPS, seed=args.seed, body=body)
        frames = list(SHOWN)
        with torch.no_grad():
            out = body(
                torch.as_tensor(motion.betas),
                torch.as_tensor(motion.pose[frames]),
                torch.as_tensor(motion.trans[frames]),
            )
        for col, frame in enumerate(frames):
            ax = axes[row, col]
            v = out.vertices[col].double().numpy()
            v[:, [0, 2]] -= motion.trans[frame, [0, 2]]  # keep travelling bodies in frame
            draw_meshes(ax, [(v, faces, SKIN)], VIEW_DEG)
            ax.axhline(-1.133, color="0.6", lw=0.5)
            ax.set_xlim(-1.0, 1.0)
            ax.set_ylim(-1.2, 1.0)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            _, ty, tz = motion.trans[frame]
            ax.set_title(f"t={frame / FPS:.1f}s  z={tz:+.2f} y={ty:+.2f}", fontsize=6)
            if col == 0:
                ax.set_ylabel(kind, fontsize=9)
    fig.suptitle(f"procedural motions, seed {args.seed}, default body (view 40° from the front)")
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=110)


if __name__ == "__main__":
    main()
