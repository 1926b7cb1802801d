"""Zhu et al. 2019's figures and table from our runs: snapshots of the common obstacle-free regions, target formations
and robots (Fig. 4), and the per-part computation times (Table I) as Markdown and LaTeX."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from stafpipe.controllers.zhu import TIMED_PARTS
from stafpipe.episode import scenario_from_yaml
from stafpipe.episode_log import EpisodeRecord
from stafpipe.errors import StafpipeError
from stafpipe.io import markdown_table
from stafpipe.plots.trajectories import SUBTEAM_COLOURS, draw_map

PART_NAMES = {
    "convex_regions": "Convex regions",
    "split_check": "Splitting checking",
    "graph_partition": "Graph partition",
    "merge_decision": "Merging decisions",
    "formation_control": "Local formation control",
}


def snapshot_times(rec: EpisodeRecord, count: int = 4) -> list[float]:
    """Default snapshot times: the first split, the first merge after it, then the end, topped up with evenly spaced
    times (Zhu's Fig. 4 shows the split, the merge and the formation after it)."""
    times: list[float] = []
    splits = [e["time"] for e in rec.events if e["kind"] == "split"]
    if splits:
        times.append(splits[0])
        merges = [e["time"] for e in rec.events if e["kind"] == "merge" and e["time"] > splits[0]]
        if merges:
            times.append(merges[0])
    times.append(float(rec.time[-1]))
    for t in np.linspace(rec.time[0], rec.time[-1], count + 2)[1:-1]:
        if len(times) >= count:
            break
        times.append(float(t))
    return sorted({round(t, 1) for t in times})[:count]


def regions_figure(rec: EpisodeRecord, times: list[float]) -> Figure:
    """One panel per time: the map, each subteam's common region (red, from the method's `regions` events), its target
    formation (black dots) and the robots (blue stars), moving obstacles as discs."""
    snapshots = [(e["time"], json.loads(e["detail"])) for e in rec.events if e["kind"] == "regions"]
    if not snapshots:
        raise StafpipeError(f"episode of {rec.method} logs no `regions` events (only method=zhu does)")
    scenario = scenario_from_yaml(rec.scenario_yaml)
    fig = Figure(figsize=(4.0 * len(times), 4.2))
    for k, t in enumerate(times):
        ax = fig.add_subplot(1, len(times), k + 1)
        draw_map(ax, scenario)
        step = int(np.searchsorted(rec.time, t, side="right") - 1)
        when, regions = max((s for s in snapshots if s[0] <= t + 1e-9), key=lambda s: s[0], default=snapshots[0])
        for _sid, vertices in regions.items():
            if len(vertices) >= 3:
                ax.add_patch(Polygon(vertices, closed=True, facecolor="red", alpha=0.25, edgecolor="red", lw=1.0))
        ax.scatter(
            rec.targets[step, :, 0], rec.targets[step, :, 1], s=10, color="k", zorder=3, label="target formation"
        )
        colours = [SUBTEAM_COLOURS[int(s) % len(SUBTEAM_COLOURS)] for s in rec.subteams[step]]
        ax.scatter(
            rec.positions[step, :, 0], rec.positions[step, :, 1], s=40, marker="*", c=colours, zorder=4, label="robots"
        )
        for m, spec in enumerate(scenario.spec.moving_obstacles):
            ax.add_patch(Circle(tuple(rec.movers[step, m]), spec.radius, color="gold", ec="k", lw=0.8, zorder=2))
        centre = rec.positions[step].mean(axis=0)
        span = max(6.0, float(np.ptp(rec.positions[step], axis=0).max()) + 6.0)
        ax.set_xlim(centre[0] - span / 2, centre[0] + span / 2)
        ax.set_ylim(centre[1] - span / 2, centre[1] + span / 2)
        ax.set_title(f"t = {rec.time[step]:.1f} s (regions of t = {when:.1f} s)", fontsize=9)
        if k == 0:
            ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    return fig


def timing_table(results: pd.DataFrame) -> pd.DataFrame:
    """Table I from the per-episode `time_<part>_{min,mean,max,std,count}` columns of an eval run's results: min of the
    minima, the cycle-weighted mean, max of the maxima and the pooled standard deviation, in ms per cycle."""
    missing = [p for p in TIMED_PARTS if f"time_{p}_mean" not in results.columns]
    if missing:
        raise StafpipeError(f"results lack the timing columns of {missing} (an eval run of method=zhu?)")
    rows = []
    for part in TIMED_PARTS:
        c = results[f"time_{part}_count"].to_numpy(float)
        mean = results[f"time_{part}_mean"].to_numpy(float)
        std = results[f"time_{part}_std"].to_numpy(float)
        used = c > 0
        if not used.any():
            rows.append(
                {
                    "Computations": PART_NAMES[part],
                    "Min.": math.nan,
                    "Mean.": math.nan,
                    "Max.": math.nan,
                    "Std.": math.nan,
                    "cycles": 0,
                }
            )
            continue
        c, mean, std = c[used], mean[used], std[used]
        grand = float((c * mean).sum() / c.sum())
        pooled = math.sqrt(float((c * (std**2 + (mean - grand) ** 2)).sum() / c.sum()))
        rows.append(
            {
                "Computations": PART_NAMES[part],
                "Min.": float(results[f"time_{part}_min"][used].min()),
                "Mean.": grand,
                "Max.": float(results[f"time_{part}_max"][used].max()),
                "Std.": pooled,
                "cycles": int(c.sum()),
            }
        )
    table = pd.DataFrame(rows)
    total = {
        "Computations": "Total (sum of means)",
        "Min.": math.nan,
        "Mean.": float(np.nansum(table["Mean."])),
        "Max.": math.nan,
        "Std.": math.nan,
        "cycles": int(table["cycles"].max()),
    }
    return pd.concat([table, pd.DataFrame([total])], ignore_index=True)


def latex_table(table: pd.DataFrame, caption: str) -> str:
    """Table I as a LaTeX tabular (booktabs), times to 0.001 ms, missing values as --."""

    def cell(v: object) -> str:
        return "--" if isinstance(v, float) and math.isnan(v) else (f"{v:.3f}" if isinstance(v, float) else str(v))

    cols = list(table.columns)
    lines = [
        r"\begin{table}[t]",
        r"\centering",
        rf"\caption{{{caption}}}",
        r"\begin{tabular}{l" + "r" * (len(cols) - 1) + "}",
        r"\toprule",
        " & ".join(cols) + r" \\",
        r"\midrule",
    ]
    lines += [" & ".join(cell(v) for v in row) + r" \\" for row in table.itertuples(index=False)]
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}", ""]
    return "\n".join(lines)


def markdown_timing(table: pd.DataFrame) -> str:
    """Table I as Markdown (missing values as --)."""
    return markdown_table(table.astype(object).where(table.notna(), "--"), digits=3)
