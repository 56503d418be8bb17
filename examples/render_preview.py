"""Preview of the default body with the T-shirt template: in the rest T-pose, and in an
AMASS-like pose (left arm raised, right knee bent, a step) dressed by the ``lbs+postprocess``
baseline. Front and three-quarter views.

Run: ``python examples/render_preview.py [-o docs/preview.png]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import torch

from usd_garment.body import SMPL_JOINT_NAMES, load_body_model
from usd_garment.eval.render import CLOTH, SKIN, draw_meshes
from usd_garment.garment.library import load_template
from usd_garment.methods import get_method
from usd_garment.motion.sequence import SmplMotion

J = {name: i for i, name in enumerate(SMPL_JOINT_NAMES)}


def amass_like_pose() -> np.ndarray:
    """``(24, 3)`` axis-angles: left arm raised, right knee bent, left hip forward, elbows bent."""
    pose = np.zeros((24, 3), dtype=np.float32)
    pose[J["left_shoulder"]] = [0.0, 0.0, 1.1]
    pose[J["right_shoulder"]] = [0.0, 0.0, 1.0]
    pose[J["right_elbow"]] = [0.0, 1.2, 0.0]
    pose[J["right_hip"]] = [-0.3, 0.0, 0.0]
    pose[J["right_knee"]] = [1.2, 0.0, 0.0]
    pose[J["left_hip"]] = [-0.4, 0.0, 0.0]
    pose[J["spine2"]] = [0.15, 0.2, 0.0]
    return pose


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=Path("docs/preview.png"))
    args = parser.parse_args()
    body = load_body_model()
    template = load_template("tshirt", "high")
    pose = np.stack([np.zeros((24, 3), np.float32), amass_like_pose()])
    motion = SmplMotion(np.zeros(10, np.float32), pose, np.zeros((2, 3), np.float32), 30.0)
    garment = get_method("lbs+postprocess").predict(motion, body, template)
    with torch.no_grad():
        posed = body(torch.zeros(10), torch.as_tensor(pose)).vertices.numpy()
    faces = body.faces.numpy()
    fig, axes = plt.subplots(1, 4, figsize=(14, 5))
    titles = ("T-pose, front", "T-pose, 3/4", "AMASS-like pose, front", "AMASS-like pose, 3/4")
    for ax, (frame, view), title in zip(
        axes, ((0, 0.0), (0, 40.0), (1, 0.0), (1, 40.0)), titles, strict=True
    ):
        draw_meshes(ax, [(posed[frame], faces, SKIN), (garment[frame], template.faces, CLOTH)],
                    view)  # fmt: skip
        ax.set_xlim(-1.0, 1.0)
        ax.set_ylim(-1.2, 0.7)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(title, fontsize=10)
    fig.suptitle(f"default body ({body.name}) with the T-shirt template ({len(template.vertices)}"
                 " vertices), posed by lbs+postprocess")  # fmt: skip
    fig.tight_layout()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.output, dpi=100)


if __name__ == "__main__":
    main()
