"""Preview of what the README's first command makes: ``examples/walk.usda`` dressed by ``dress``
with its default method (the shipped learned T-shirt, ``learned+preimage``), read back from the
written garment layer and drawn with the posed body at three frames, front and three-quarter
views.

Run: ``python examples/render_preview.py [-o docs/preview.png]``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from usd_garment.body import load_body_model
from usd_garment.dress import dress
from usd_garment.eval.evaluate import posed_body_vertices
from usd_garment.eval.render import CLOTH, SKIN, draw_meshes
from usd_garment.methods.learned import default_method
from usd_garment.usd.garment_read import read_garment_layer
from usd_garment.usd.read import read_smpl_motion

EXAMPLE = Path(__file__).resolve().parent / "walk.usda"
FRAMES = (20, 60, 100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("docs/preview.png"))
    args = parser.parse_args()
    body = load_body_model()
    method = default_method("tshirt", "high")
    with tempfile.TemporaryDirectory() as tmp:
        result = dress(EXAMPLE, Path(tmp) / "walk_tshirt.usdc", method=method)
        garment, garment_faces, _ = read_garment_layer(Path(tmp) / "walk_tshirt.usdc")
    motion, _ = read_smpl_motion(EXAMPLE, body)
    posed = posed_body_vertices(body, motion)
    faces = body.faces.numpy()
    fig, axes = plt.subplots(2, len(FRAMES), figsize=(4 * len(FRAMES), 9))
    for row, view in enumerate((0.0, 40.0)):
        for ax, frame in zip(axes[row], FRAMES, strict=True):
            centre = posed[frame].mean(axis=0)
            draw_meshes(ax, [(posed[frame] - centre, faces, SKIN),
                             (garment[frame] - centre, garment_faces, CLOTH)], view)  # fmt: skip
            ax.set_xlim(-0.9, 0.9)
            ax.set_ylim(-1.0, 0.9)
            ax.set_aspect("equal")
            ax.set_axis_off()
            ax.set_title(f"frame {frame}, {'front' if view == 0 else '3/4'}", fontsize=10)
    fps = result.frames / sum(result.seconds.values())
    fig.suptitle(f"examples/walk.usda dressed by 'usd-garment dress' ({result.method}, "
                 f"{result.vertices} vertices, {fps:.0f} frames/s end to end)")  # fmt: skip
    fig.tight_layout()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=90)


if __name__ == "__main__":
    main()
