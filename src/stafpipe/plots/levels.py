"""Variants of one method side by side (`eval.label`): SR, collisions per episode and CFI(0.5) per map, mean and 95 %
CI, one bar per variant: the figure of the `staf_levels` ablation (docs/staf_planned.md)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from stafpipe.plots.staf_tables import method_label


def levels_figure(table: pd.DataFrame):
    """Three panels (SR %, collisions / episode, CFI 0.5 %) of a `staf_tables.summary_table` with a `label` column."""
    from matplotlib.figure import Figure

    label = table["label"].fillna("").astype(str)
    table = table.assign(
        where=table["scenario"].astype(str)
        + np.where(table["scenario"].astype(str).str.startswith("corridor"), " " + table["formation"].astype(str), ""),
        variant=table["method"].astype(str).map(method_label) + np.where(label.str.len() > 0, " (" + label + ")", ""),
    )
    table = table.drop_duplicates(["variant", "where"])  # one bar per variant and map (the first run of a repeat)
    places = list(dict.fromkeys(table["where"]))
    labels = list(dict.fromkeys(table["variant"]))
    fig = Figure(figsize=(max(8.0, 0.75 * len(places) + 2), 8.0))
    width = 0.8 / max(len(labels), 1)
    for k, (metric, scale, title) in enumerate(
        (("sr", 100, "SR %"), ("collisions", 1, "collisions / episode"), ("cfi_0.5", 100, "CFI(0.5) %"))
    ):
        ax = fig.add_subplot(3, 1, k + 1)
        for j, label in enumerate(labels):
            part = table[table["variant"] == label].set_index("where").reindex(places)
            ax.bar(
                np.arange(len(places)) + (j - (len(labels) - 1) / 2) * width,
                scale * part[metric].to_numpy(float),
                width,
                yerr=scale * np.nan_to_num(part[f"{metric}_ci95"].to_numpy(float)),
                capsize=2,
                label=label,
            )
        ax.set_ylabel(title)
        ax.set_xticks(np.arange(len(places)))
        ax.set_xticklabels(places if k == 2 else [], rotation=35, ha="right", fontsize=7)
        if k == 0:
            ax.legend(fontsize=7, ncol=len(labels))
    fig.tight_layout()
    return fig
