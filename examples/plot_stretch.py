"""Where simulated garments are over-stretched: frames of one or more garment layers simulated
on the same body layer, the triangles with an edge longer than ``--ratio`` × its rest length
(the template graded to the body's shape, as the simulator grades it) in red, zoomed on them,
from the front and the back; and, per layer, the largest edge stretch and the frames with an
edge above the ratio (printed).

Run: ``python examples/plot_stretch.py BODY.usdc GARMENT.usdc [GARMENT.usdc ...] --frames 28,52
[-o stretch.png] [--ratio 2]``. ``docs/snag_dress.png`` is
``python examples/plot_stretch.py scratch/dataset_dress_v7s/m03_s0_body.usdc
scratch/dataset_dress_v7s/m03_s0_dress.usdc scratch/dataset_dress_v7s_e/m03_s0_dress.usdc
--frames 28,52 -o docs/snag_dress.png`` (``docs/simulation.md``, "Snagged hems").
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
from usd_garment.eval.render import CLOTH, SKIN, draw_meshes, view_axes
from usd_garment.garment.library import load_template
from usd_garment.garment.mesh_ops import face_edges
from usd_garment.methods.simulation import shape_offsets
from usd_garment.sim.checks import edge_lengths, unique_edges
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion

VIEWS = (("front", 0.0), ("back", 180.0))
RED = (0.9, 0.1, 0.1)
#: Margin around the red triangles in a zoomed view (m).
MARGIN = 0.15


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("body", type=Path)
    parser.add_argument("garments", nargs="+", type=Path)
    parser.add_argument("--frames", required=True, help="comma-separated frame indices")
    parser.add_argument("--ratio", type=float, default=2.0)
    parser.add_argument("-o", "--output", type=Path, default=Path("stretch.png"))
    args = parser.parse_args()
    frames = [int(f) for f in args.frames.split(",")]

    body = load_body_model()
    motion, _ = read_smpl_motion(args.body, body)
    layers = [read_garment_layer(path) for path in args.garments]
    template = load_template(layers[0][2].mesh.rsplit("/", 1)[-1], "high")
    rest = template.vertices + shape_offsets(body, template.vertices, motion.betas)
    edges = unique_edges(template.faces)
    rest_lengths = edge_lengths(rest, edges)
    # Each layer's triangle edges and their rest lengths, face by face (for the red faces).
    corners = [face_edges(faces) for _, faces, _ in layers]
    rest_corners = [edge_lengths(rest, c) for c in corners]
    for path, (points, _, _) in zip(args.garments, layers, strict=True):
        largest = (edge_lengths(points, edges) / rest_lengths).max(axis=1)
        print(f"{path}: largest edge {largest.max():.2f}x, frames with an edge above "
              f"{args.ratio:g}x: {int((largest > args.ratio).sum())} of {len(points)}")  # fmt: skip

    columns = [(t, view) for t in frames for view in VIEWS]
    fig, axes = plt.subplots(len(layers), len(columns), squeeze=False,
                             figsize=(2.6 * len(columns), 3.0 * len(layers)))  # fmt: skip
    for col, (t, (view_name, view)) in enumerate(columns):
        with torch.no_grad():
            posed = body(torch.as_tensor(motion.betas), torch.as_tensor(motion.pose[t : t + 1]),
                         torch.as_tensor(motion.trans[t : t + 1])).vertices[0].numpy()  # fmt: skip
        right, _ = view_axes(view)
        red = []  # the red vertices of every layer: each column zooms on the same box
        for row, (path, (points, faces, _)) in enumerate(zip(args.garments, layers, strict=True)):
            stretch = edge_lengths(points[t], corners[row]) / rest_corners[row]
            over = stretch.reshape(-1, 3).max(axis=1) > args.ratio
            red.append(points[t][np.unique(faces[over])])
            ax = axes[row, col]
            draw_meshes(ax, [(posed, body.faces.numpy(), SKIN), (points[t], faces[~over], CLOTH),
                             (points[t], faces[over], RED)], view)  # fmt: skip
            ax.set_aspect("equal")
            ax.autoscale()
            ax.axis("off")
            ax.set_title(f"{path.parent.name}/{path.stem}\nframe {t}, {view_name}: "
                         f"{int(over.sum())} red", fontsize=7)  # fmt: skip
        box = np.concatenate(red)
        if len(box):
            for ax in axes[:, col]:
                ax.set_xlim((box @ right).min() - MARGIN, (box @ right).max() + MARGIN)
                ax.set_ylim(box[:, 1].min() - MARGIN, box[:, 1].max() + MARGIN)
    fig.tight_layout()
    fig.savefig(args.output, dpi=110)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
