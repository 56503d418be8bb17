"""Pictures of training runs: every stage's curves, and the paper's Fig. 4 (collisions of the
VAE on held-out data per epoch, with and without the self-supervised term). Needs matplotlib
(the ``[train]`` extra); drawn off-screen to PNG files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from usd_garment.atomic import atomic_output
from usd_garment.eval.plotting import pyplot

#: Curves drawn per stage: (history key, label).
CURVES: dict[str, tuple[tuple[str, str], ...]] = {
    "pose": (("train_mse", "train feature MSE"), ("val_mse", "validation feature MSE")),
    "vae": (
        ("rec", "train L_rec (m per garment)"),
        ("collision_random", "train L_col, random z"),
        ("val_rec_l1_mm", "validation reconstruction (mm)"),
        ("val_rand_inside_pct", "validation random z inside (%)"),
    ),
    "regressor": (
        ("train_loss", "train loss"),
        ("val_pos", "validation L_pos"),
        ("val_vertex_mm", "validation vertex error (mm)"),
    ),
}


def plot_curves(records: dict[str, dict[str, Any]], path: str | Path) -> None:
    """One panel per trained stage of ``records`` (stage → record of ``train_stage``), its
    curves over epochs on a log scale, written to the PNG ``path``."""
    plt = pyplot()
    stages = [s for s in CURVES if s in records]
    fig, axes = plt.subplots(1, max(len(stages), 1), figsize=(5 * max(len(stages), 1), 3.8))
    axes = [axes] if len(stages) <= 1 else list(axes)
    for ax, stage in zip(axes, stages, strict=False):
        rows = records[stage]["history"]["epochs"]
        for key, label in CURVES[stage]:
            points = [(r["epoch"], r[key]) for r in rows if r.get(key) is not None and r[key] > 0]
            if points:
                ax.plot(*zip(*points, strict=True), label=label)
        ax.set_yscale("log")
        ax.set_xlabel("epoch")
        ax.set_title(stage)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def plot_collisions(runs: dict[str, list[dict[str, Any]]], path: str | Path) -> None:
    """The paper's Fig. 4: share of vertices inside the canonical body per epoch, for
    reconstructions of held-out garments and for decodings of random latents, one line pair per
    run (label → the VAE's history rows), written to the PNG ``path``."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=False)
    for label, rows in runs.items():
        epochs = [r["epoch"] for r in rows]
        # a dot at each epoch: a run of one epoch (a quick try) has no line to draw
        style = {"label": label, "marker": "o", "markersize": 3}
        axes[0].plot(epochs, [r.get("val_rec_inside_pct") for r in rows], **style)
        axes[1].plot(epochs, [r.get("val_rand_inside_pct") for r in rows], **style)
    axes[0].set_title("held-out garments, reconstructed")
    axes[1].set_title("random latents z ~ N(0, I), decoded")
    for ax in axes:
        ax.set_xlabel("epoch")
        ax.set_ylabel("vertices inside the body (%)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
