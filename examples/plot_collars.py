"""Front view of a CMU capture on the default body with the collars aimed along the BVH's
(``--collars aimed``: the shoulders shrugged) and turned from SMPL's rest collars
(``--collars rest``, ``import-bvh``'s default), beside SMPL's rest (``docs/mocap.md``, "The
collars: aimed or from the rest").

Run: ``python examples/plot_collars.py [BVH] [FRAME] [-o docs/collars.png]`` (default: the
T-pose frame 0 and frame 200 of ``examples/mocap/cmu_14_04.bvh.xz``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib
import numpy as np
import torch

from usd_garment.body import load_body_model
from usd_garment.body.joints import SMPL_JOINT_NAMES
from usd_garment.eval.render import SKIN, draw_meshes
from usd_garment.motion.bvh import load_bvh

matplotlib.use("Agg")
import matplotlib.pyplot as plt

NECK = SMPL_JOINT_NAMES.index("neck")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bvh", nargs="?", default="examples/mocap/cmu_14_04.bvh.xz")
    parser.add_argument("frame", nargs="?", type=int, default=200)
    parser.add_argument("-o", "--output", type=Path, default=Path("docs/collars.png"))
    args = parser.parse_args()
    body = load_body_model()
    frames = (0, args.frame + 1)
    before, _ = load_bvh(args.bvh, body, frames=frames, arm_clearance=None, collars="aimed")
    now, _ = load_bvh(args.bvh, body, frames=frames, arm_clearance=None, collars="rest")
    cells = [
        (np.zeros((24, 3)), "SMPL rest"),
        (before.pose[0], "T-pose frame, --collars aimed"),
        (now.pose[0], "T-pose frame, --collars rest"),
        (before.pose[-1], f"frame {args.frame}, --collars aimed"),
        (now.pose[-1], f"frame {args.frame}, --collars rest"),
    ]
    fig, axes = plt.subplots(1, len(cells), figsize=(4 * len(cells), 4.2))
    faces = body.faces.numpy()
    for ax, (pose, title) in zip(axes, cells, strict=True):
        pose = np.array(pose, dtype=np.float32)
        pose[0] = 0.0  # facing the camera
        with torch.no_grad():
            out = body(torch.zeros(1, 10), torch.from_numpy(pose)[None], torch.zeros(1, 3))
        vertices = out.vertices[0].numpy() - out.joints[0, NECK].numpy()
        draw_meshes(ax, [(vertices, faces, SKIN)], 0.0)
        ax.set_xlim(-0.45, 0.45)
        ax.set_ylim(-0.45, 0.3)
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=10)
        ax.axis("off")
    fig.suptitle(f"{Path(args.bvh).name} on the default body (root rotation zeroed, neck at 0)")
    fig.savefig(args.output, dpi=60, bbox_inches="tight")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
