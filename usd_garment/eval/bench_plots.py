"""Pictures of a bench run: speed against accuracy with the Pareto front (frames/s on a log scale
against inside-elsewhere share, and against mean error to the simulation), and the per-frame
collision curves of each input (the paper's Fig. 3)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from usd_garment.atomic import atomic_output
from usd_garment.eval.bench import BenchRow, ChartPoint, chart_points, pareto_front
from usd_garment.eval.plotting import pyplot

#: Marker of each level of detail.
LOD_MARKERS = {"high": "o", "medium": "s", "low": "^"}


def plot_chart(rows: Sequence[BenchRow], path: str | Path, title: str = "") -> None:
    """Two panels, a point per method × level of detail, the Pareto front of each drawn as a
    line: inside elsewhere (% of vertices) and mean vertex error to the simulation (mm) on the
    y axis, frames/s (log) on the x axis. Written to the PNG ``path``."""
    plt = pyplot()
    points = chart_points(rows)
    labels = list(dict.fromkeys(p.label for p in points))
    colours = {label: plt.cm.tab10(k % 10) for k, label in enumerate(labels)}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4))
    panels = (
        ("inside_elsewhere_share", 100.0, "inside the body elsewhere (% of vertices)"),
        ("reference_mm", 1.0, "mean vertex error to the simulation (mm)"),
    )
    for ax, (key, scale, ylabel) in zip(axes, panels, strict=True):
        _draw_panel(ax, points, key, scale, colours)
        ax.set_xscale("log")
        ax.set_xlabel("frames per second, end to end (log)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
    handles = [
        plt.Line2D([], [], color=colours[label], marker="o", linestyle="", label=label)
        for label in labels
    ] + [
        plt.Line2D([], [], color="grey", marker=marker, linestyle="", label=f"lod {lod}")
        for lod, marker in LOD_MARKERS.items()
        if any(p.lod == lod for p in points)
    ]
    axes[1].legend(handles=handles, fontsize=7, loc="best")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _draw_panel(
    ax: Any, points: list[ChartPoint], key: str, scale: float, colours: dict[str, Any]
) -> None:
    speed = [p.frames_per_second for p in points]
    cost = [scale * getattr(p, key) for p in points]
    for p, y in zip(points, cost, strict=True):
        if np.isfinite(y) and np.isfinite(p.frames_per_second):
            ax.plot(p.frames_per_second, y, LOD_MARKERS.get(p.lod, "o"), color=colours[p.label])
    front = pareto_front(speed, cost)
    if len(front) > 1:
        ax.plot([speed[i] for i in front], [cost[i] for i in front], "k--", lw=0.8,
                label="Pareto front")  # fmt: skip
    elif not front:
        ax.text(0.5, 0.5, "no figures", transform=ax.transAxes, ha="center", color="grey")


def plot_collision_curves(rows: Sequence[BenchRow], path: str | Path) -> None:
    """Per input, the share of vertices inside the body elsewhere per frame for each method at
    its highest level of detail run (one panel per input), written to the PNG ``path``."""
    plt = pyplot()
    inputs = list(dict.fromkeys(r.input for r in rows))
    fig, axes = plt.subplots(len(inputs), 1, figsize=(9, 2.6 * max(len(inputs), 1)), squeeze=False)
    for ax, name in zip(axes[:, 0], inputs, strict=True):
        seen: set[str] = set()
        for r in rows:
            if r.input != name or r.error or r.label in seen:
                continue
            seen.add(r.label)
            ax.plot(100.0 * np.asarray(r.inside_elsewhere), lw=1, label=f"{r.label} ({r.lod})")
        ax.set_title(name, fontsize=9)
        ax.set_ylabel("inside elsewhere (%)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("frame")
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
