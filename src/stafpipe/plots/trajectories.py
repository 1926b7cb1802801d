"""STAF-Fig.-4-style trajectory plots: the static map in grey, each robot's path a line coloured by its subteam at each
moment, start (circle) and goal (cross) of every robot, moving obstacles dashed. Read from the episode MCAP logs
alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from stafpipe.episode import scenario_from_yaml
from stafpipe.episode_log import EpisodeRecord
from stafpipe.scenario import Scenario

OBSTACLE_GREY = "0.6"
SUBTEAM_COLOURS = [f"C{k}" for k in range(10)]


def draw_map(ax: Axes, scenario: Scenario) -> None:
    """Static obstacles in grey: solid polygons, discs and thick segments; world walls as a thin frame."""
    for poly in scenario.polygons:
        ax.add_patch(Polygon(poly, closed=True, color=OBSTACLE_GREY, lw=0))
    if scenario.occupancy is not None:  # a ROS map's occupied cells, in the map's frame
        from matplotlib.colors import ListedColormap
        from matplotlib.transforms import Affine2D

        grid = scenario.occupancy
        h, w = grid.occupied.shape
        frame = Affine2D().rotate(grid.origin[2]).translate(*grid.origin[:2]) + ax.transData
        ax.imshow(
            np.ma.masked_equal(grid.occupied.astype(np.int8), 0),
            origin="lower",
            interpolation="nearest",
            cmap=ListedColormap([OBSTACLE_GREY]),
            extent=(0, w * grid.resolution, 0, h * grid.resolution),
            transform=frame,
        )
    for cap in scenario.capsules:
        a, b = np.asarray(cap.a), np.asarray(cap.b)
        if cap.radius <= 0:
            continue  # polygon edges and walls: drawn as the polygons and the frame
        if np.allclose(a, b):
            ax.add_patch(Circle(tuple(a), cap.radius, color=OBSTACLE_GREY, lw=0))
        else:  # a capsule: its rectangle and two end discs
            d = (b - a) / np.linalg.norm(b - a)
            n = np.array([-d[1], d[0]]) * cap.radius
            ax.add_patch(Polygon([a + n, b + n, b - n, a - n], closed=True, color=OBSTACLE_GREY, lw=0))
            for end in (a, b):
                ax.add_patch(Circle(tuple(end), cap.radius, color=OBSTACLE_GREY, lw=0))
    w = scenario.spec.world
    ax.plot([w.xmin, w.xmax, w.xmax, w.xmin, w.xmin], [w.ymin, w.ymin, w.ymax, w.ymax, w.ymin], color="0.3", lw=1.5)
    ax.set_xlim(w.xmin, w.xmax)
    ax.set_ylim(w.ymin, w.ymax)
    ax.set_aspect("equal")


def trajectory_figure(rec: EpisodeRecord, title: str = "") -> Figure:
    """One episode: map, robot paths coloured by subteam over time, starts, goals, moving obstacles. When the team
    split, one more panel per subteam of its first split with each of its robots' paths in its own colour (STAF Fig. 4,
    second and third subfigures)."""
    scenario = scenario_from_yaml(rec.scenario_yaml)
    w = scenario.spec.world
    width = 8.0
    pos, sub = rec.positions, rec.subteams  # (T, n, 2), (T, n)
    split = [k for k in range(len(sub)) if len(np.unique(sub[k])) > 1]
    teams = [np.flatnonzero(sub[split[0]] == j) for j in np.unique(sub[split[0]])] if split else []
    height = max(2.5, width * (w.ymax - w.ymin) / (w.xmax - w.xmin)) + 0.6
    fig = Figure(figsize=(width, height * (1 + len(teams))))
    axes = fig.subplots(1 + len(teams), 1, squeeze=False)[:, 0]
    ax = axes[0]
    draw_map(ax, scenario)
    for i in range(pos.shape[1]):
        segments = np.stack([pos[:-1, i], pos[1:, i]], axis=1)  # (T-1, 2, 2)
        colours = [SUBTEAM_COLOURS[int(s) % len(SUBTEAM_COLOURS)] for s in sub[:-1, i]]
        ax.add_collection(LineCollection(segments, colors=colours, linewidths=1.2))  # type: ignore[arg-type]
    ax.scatter(pos[0, :, 0], pos[0, :, 1], s=14, facecolors="none", edgecolors="k", linewidths=0.8, label="start")
    ax.scatter(rec.goal[:, 0], rec.goal[:, 1], s=14, marker="x", color="k", linewidths=0.8, label="goal")
    if rec.movers.size:
        for m in range(rec.movers.shape[1]):
            ax.plot(rec.movers[:, m, 0], rec.movers[:, m, 1], ls="--", color="0.2", lw=1.0)
    for sid in np.unique(sub):
        ax.plot([], [], color=SUBTEAM_COLOURS[int(sid) % len(SUBTEAM_COLOURS)], label=f"subteam {int(sid)}")
    ax.legend(loc="upper left", fontsize=7, ncols=2, framealpha=0.8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    for j, (panel, idx) in enumerate(zip(axes[1:], teams, strict=True)):
        draw_map(panel, scenario)
        for k, robot in enumerate(idx):
            panel.plot(pos[:, robot, 0], pos[:, robot, 1], color=f"C{k % 10}", lw=1.0, label=f"robot {robot}")
        panel.set_title(f"subteam {j}: robots {', '.join(str(i) for i in idx)}", fontsize=8)
        panel.legend(loc="upper left", fontsize=6, ncols=3, framealpha=0.8)
    metrics = rec.metrics or {}
    summary = ", ".join(f"{k} {metrics[k]:.2f}" for k in ("sr", "tt", "cfi_0.1") if k in metrics)
    ax.set_title(
        title or f"{rec.method} on {scenario.spec.name}, seed {rec.seed}" + (f" ({summary})" if summary else ""),
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def episode_files(run_dir: Path) -> list[Path]:
    """The episode logs of an eval run directory, in episode order."""
    return sorted((run_dir / "episodes").glob("*.mcap")) if (run_dir / "episodes").is_dir() else []


def connectivity_figure(records: list[EpisodeRecord]) -> Figure:
    """Cezayirli Fig. 4 style: number of links (pairs that sense each other: within the sensing radius and, where the
    run's sensing has occlusion, not hidden by a robot in between) over time for each episode, with the N - 1 links a
    connected team cannot go below, and the algebraic connectivity lambda2 below it."""
    from stafpipe.metrics import connectivity

    fig = Figure(figsize=(7.0, 4.6))
    ax, ax2 = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    for rec in records:
        ctx = rec.context
        hide = float(ctx["robot_radius"]) if ctx.get("occlusion") else 0.0
        links, lam2 = connectivity(rec.positions, float(ctx["sensing_radius"]), hide)
        ax.plot(rec.time, links, lw=1.0, label=f"seed {rec.seed}")
        ax2.plot(rec.time, lam2, lw=1.0)
    n = records[0].positions.shape[1]
    ax.axhline(n - 1, color="k", ls="--", lw=0.8, label=f"N - 1 = {n - 1}")
    ax.set_ylabel("links")
    ax.legend(fontsize=7)
    ax2.axhline(0.0, color="k", ls="--", lw=0.8)
    ax2.set_ylabel("lambda2")
    ax2.set_xlabel("time (s)")
    fig.tight_layout()
    return fig
