"""Team partitions drawn as panels (STAF Figs. 7, 9 and 14 style): robots coloured by subteam, radius-graph edges in
grey, and each subteam's goal centre marked with a cross of its colour and an arrow from its start centre."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from stafpipe.highlevel.graphs import radius_edges

COLOURS = [f"C{k}" for k in range(10)]


def partition_figure(parts: pd.DataFrame, radius: float = 2.0, ncols: int = 4, title: str = "") -> Figure:
    """One panel per `panel` value of `parts` (columns panel, robot, x, y, goal_x, goal_y, subteam), in order."""
    panels = list(dict.fromkeys(parts["panel"]))
    ncols = min(ncols, len(panels))
    nrows = math.ceil(len(panels) / ncols)
    fig = Figure(figsize=(3.0 * ncols, 3.0 * nrows + (0.4 if title else 0)))
    for k, name in enumerate(panels):
        ax = fig.add_subplot(nrows, ncols, k + 1)
        g = parts[parts["panel"] == name].sort_values("robot")
        pos = g[["x", "y"]].to_numpy(float)
        goal = g[["goal_x", "goal_y"]].to_numpy(float)
        sub = g["subteam"].to_numpy(int)
        for i, j in radius_edges(pos, radius).T:
            if i < j:
                ax.plot(*pos[[i, j]].T, color="0.85", lw=0.6, zorder=1)
        centre = pos.mean(0)
        for s in np.unique(sub):
            c = COLOURS[int(s) % len(COLOURS)]
            ax.scatter(pos[sub == s, 0], pos[sub == s, 1], s=36, color=c, zorder=3, label=f"subteam {s}")
            # the goal centre, drawn relative to the team so that panels stay compact
            d = goal[sub == s].mean(0) - goal.mean(0) + centre + _unit(goal.mean(0) - centre) * _span(pos) * 0.9
            ax.annotate("", xy=d, xytext=pos[sub == s].mean(0), arrowprops={"arrowstyle": "->", "color": c, "lw": 0.8})
            ax.scatter(d[0], d[1], marker="x", s=30, color=c, zorder=3)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(str(name), fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-9)


def _span(pos: np.ndarray) -> float:
    return float(np.ptp(pos, axis=0).max()) + 1.0


def ari_figure(summary: pd.DataFrame) -> Figure:
    """Partition consistency under position noise (STAF Fig. 14): adjusted Rand index vs sigma, mean and 95 % CI."""
    fig = Figure(figsize=(4.5, 3.2))
    ax = fig.add_subplot()
    ax.errorbar(summary["sigma"], summary["ari"], yerr=summary["ari_ci95"].fillna(0), marker="o", capsize=3)
    ax.set_xlabel("position noise sigma (m)")
    ax.set_ylabel("adjusted Rand index vs noise-free cut")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig
