"""The adaptation figure: each subteam's scale and type integrity over an episode (stafpipe/adaptation.py)."""

from __future__ import annotations

import pandas as pd
from matplotlib.figure import Figure


def adaptation_figure(series: pd.DataFrame, title: str) -> Figure:
    """Two panels over time, one line per subteam (the full team after the regroup is subteam 0 again): the scale
    (1: the formation at the scenario's spacing) and the type integrity; the samples in a passage shaded."""
    fig = Figure(figsize=(7.0, 4.6))
    axes = [fig.add_subplot(2, 1, k + 1) for k in range(2)]
    for (team, robots), rows in series.groupby(["subteam", "robots"]):
        for ax, column in zip(axes, ("scale", "integrity"), strict=True):
            ax.plot(rows["time"], rows[column], ".", markersize=2, label=f"subteam {team} ({robots} robots)")
    passage = series[series["in_passage"].astype(bool)]["time"]
    for ax, label in zip(axes, ("scale (mean gap / nominal)", "type integrity"), strict=True):
        if len(passage):
            ax.axvspan(float(passage.min()), float(passage.max()), color="0.9", zorder=0)
        ax.set_ylabel(label, fontsize=8)
    axes[0].axhline(1.0, color="0.5", linewidth=0.6)
    axes[1].set_ylim(-0.05, 1.05)
    axes[1].set_xlabel("time (s); shaded: some robot in a passage")
    axes[0].set_title(title, fontsize=9)
    axes[0].legend(fontsize=6, markerscale=4)
    fig.tight_layout()
    return fig
