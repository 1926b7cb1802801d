"""STAF's result tables from eval runs, ours beside the paper's (STAF, Table 1; Table 2 is only
described in the text: "a 100% success rate across all formations" for every subteam).

One row per (run, method, formation, team size, drive, scenario) group of episodes (a run: one eval directory, so
a corridor made narrower stays apart from the original; the paper's numbers only beside runs on its own map): mean
and 95 % confidence half-width (Student t) of SR, TT, CFI at sigma 0.5 / 0.1 / 0.01, TT over its lower bound,
collisions per episode, and the share of episodes in which every robot succeeded.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

from stafpipe.metrics import CFI_SIGMAS

# STAF Table 1 (Gazebo, 10 robots, corridor): SR %, TT s, CFI % at sigma < 0.5, 0.1, 0.01
PAPER_TABLE1: dict[tuple[str, str], tuple[float, float, float, float, float]] = {
    ("dgnn", "circle"): (100.00, 68.70, 60.41, 58.91, 58.91),
    ("dgnn", "wedge"): (100.00, 82.70, 47.85, 42.33, 41.92),
    ("dgnn", "line"): (100.00, 72.61, 27.90, 20.16, 20.16),
    ("lf", "circle"): (40.00, 27.40, 67.28, 64.54, 62.69),
    ("lf", "wedge"): (70.00, 26.50, 69.70, 62.11, 59.47),
    ("lf", "line"): (60.00, 30.10, 63.76, 55.89, 55.89),
    ("staf", "circle"): (100.00, 102.10, 87.79, 80.12, 80.12),
    ("staf", "wedge"): (100.00, 69.30, 80.52, 80.51, 80.50),
    ("staf", "line"): (100.00, 111.50, 91.45, 80.06, 78.93),
}
"""Keyed by the paper's methods: ("staf", ...) is the paper's STAF, the numbers a `method=staf` row stands beside."""
PAPER_METHOD = {"staf_planned": "staf"}
"""Our methods compared with another paper method's numbers: STAF-planned (ours, the plan + learned low level)
against the paper's STAF. A method not named here is compared with its own (dgnn, lf, staf)."""
LABELS = {"staf_planned": "STAF-planned (ours)"}
"""How a method's rows are named in the tables and figures (others: the method's name)."""
METRICS = (
    "sr",
    "tt",
    "tt_arrived",
    *(f"cfi_{s:g}" for s in CFI_SIGMAS),
    *(f"cfi_printed_{s:g}" for s in CFI_SIGMAS),
    *(f"cfi_passage_{s:g}" for s in CFI_SIGMAS),
    "tt_ratio",
    "collisions",
)
GROUP = ["run", "method", "label", "formation", "n", "drive", "scenario", "paper_cell"]


def paper_key(method: str, formation: str) -> tuple[str, str]:
    """The key of the paper's Table 1 cell that `method`'s row of `formation` is compared with (`PAPER_METHOD`)."""
    return PAPER_METHOD.get(method, method), formation


def method_label(method: str) -> str:
    """A method's name in a table or figure: `LABELS`, a subteam's suffix (`-sub1`, Table 2) kept."""
    base, sep, sub = method.partition("-sub")
    return LABELS.get(base, base) + sep + sub


def mean_ci(values: pd.Series) -> tuple[float, float]:
    v = values.dropna().to_numpy(float)
    if len(v) == 0:
        return math.nan, math.nan
    if len(v) == 1:
        return float(v[0]), math.nan
    return float(v.mean()), float(stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / math.sqrt(len(v)))


def summary_table(results: pd.DataFrame, prefix: str = "") -> pd.DataFrame:
    """Mean and CI of each metric per group; `prefix` = "sub1_" etc. reads a subteam's columns (Table 2)."""
    rows = []
    if "label" in results:  # runs made before eval.label existed have none
        results = results.assign(label=results["label"].fillna(""))
    for key, group in results.groupby([c for c in GROUP if c in results], sort=False):
        row = dict(zip([c for c in GROUP if c in results], key if isinstance(key, tuple) else (key,), strict=True))
        row["episodes"] = len(group)
        row["eta"] = float(group["eta"].mean()) if "eta" in group else math.nan
        row["all_succeeded"] = float((group["sr"] >= 1.0).mean())
        for metric in METRICS:
            if prefix and metric == "tt_arrived":  # a team-level reading; subteams have their own TT
                continue
            column = f"{prefix}{metric}" if metric in ("sr", "tt") or metric.startswith("cfi") else metric
            if column in group:
                row[metric], row[f"{metric}_ci95"] = mean_ci(group[column])
        rows.append(row)
    return pd.DataFrame(rows)


def _cell(mean: float, ci: float, scale: float = 1.0, digits: int = 1) -> str:
    if not np.isfinite(mean):
        return "-"
    text = f"{mean * scale:.{digits}f}"
    return text + (f" ± {ci * scale:.{digits}f}" if np.isfinite(ci) else "")


def markdown(table: pd.DataFrame, title: str, paper: bool = True) -> str:
    """The table as Markdown: ours (mean ± 95 % CI; SR and CFI in %) and the paper's value in brackets."""
    head = [
        "method",
        "scenario",
        "eta m",
        "formation",
        "n",
        "drive",
        "episodes",
        "SR %",
        "TT s",
        "TT of arrivals s",
        "CFI 0.5 %",
        "CFI 0.1 %",
        "CFI 0.01 %",
        "CFI as printed 0.5 / 0.1 / 0.01 %",
        "CFI in the passage 0.5 / 0.1 / 0.01 %",
        "TT / bound",
        "collisions",
        "all robots ok",
    ]
    lines = [f"### {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for _, r in table.iterrows():
        eta = r.get("eta", math.nan)
        label = r.get("label", "")
        labelled = isinstance(label, str) and bool(label)  # a variant of ours (e.g. m-auto): not the paper's setup
        papers_cell = r.get("n") == 10 and bool(r.get("paper_cell", False)) and not labelled  # the paper's map, team
        ref = PAPER_TABLE1.get(paper_key(str(r["method"]), str(r["formation"]))) if paper and papers_cell else None
        cells = [
            _cell(r.get("sr", math.nan), r.get("sr_ci95", math.nan), 100),
            _cell(r.get("tt", math.nan), r.get("tt_ci95", math.nan)),
        ]
        cells += [_cell(r.get(f"cfi_{s:g}", math.nan), r.get(f"cfi_{s:g}_ci95", math.nan), 100) for s in CFI_SIGMAS]
        if ref is not None:
            cells = [f"{c} [{p:.1f}]" for c, p in zip(cells, ref, strict=True)]
        cells.insert(2, _cell(r.get("tt_arrived", math.nan), r.get("tt_arrived_ci95", math.nan)))
        printed = [r.get(f"cfi_printed_{s:g}", math.nan) for s in CFI_SIGMAS]  # means; CIs in table.csv
        cells.append(" / ".join(f"{100 * v:.1f}" for v in printed) if np.all(np.isfinite(printed)) else "-")
        passage = [r.get(f"cfi_passage_{s:g}", math.nan) for s in CFI_SIGMAS]  # runs before it existed: "-"
        cells.append(" / ".join(f"{100 * v:.1f}" for v in passage) if np.all(np.isfinite(passage)) else "-")
        cells += [
            _cell(r.get("tt_ratio", math.nan), r.get("tt_ratio_ci95", math.nan), 1, 2),
            _cell(r.get("collisions", math.nan), r.get("collisions_ci95", math.nan), 1, 2),
            f"{100 * r['all_succeeded']:.0f} %",
        ]
        name = method_label(str(r["method"]))
        method = f"{name} ({label})" if labelled else name
        lines.append(
            "| "
            + " | ".join(
                [
                    method,
                    str(r.get("scenario", "")),
                    _cell(eta, math.nan, 1, 2),
                    str(r["formation"]),
                    str(r.get("n", "")),
                    str(r.get("drive", "")),
                    str(r["episodes"]),
                    *cells,
                ]
            )
            + " |"
        )
    if paper:
        lines += [
            "",
            "[brackets]: STAF Table 1 (Gazebo, 10 trials per cell; beside STAF-planned (ours), the paper's STAF). Ours:"
            " mean ± 95 % CI over the episodes.",
        ]
    return "\n".join(lines) + "\n"


def subteam_tables(results: pd.DataFrame) -> pd.DataFrame:
    """Table 2: one row per (group, subteam) of the runs whose team split."""
    parts = []
    for j in range(1, 5):
        if f"sub{j}_sr" not in results:
            break
        t = summary_table(results[results[f"sub{j}_sr"].notna()], prefix=f"sub{j}_")
        t["method"] = t["method"].astype(str) + f"-sub{j}"
        parts.append(t)
    return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


def cfi_sigma_figure(table: pd.DataFrame):
    """STAF Fig. 8(e): CFI against sigma, one line per (method, formation, team size) row of a summary table."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.0, 3.4))
    ax = fig.add_subplot()
    sigmas = [0.5, 0.1, 0.01]
    for _, r in table.iterrows():
        means = [100 * r.get(f"cfi_{s:g}", math.nan) for s in sigmas]
        cis = [100 * r.get(f"cfi_{s:g}_ci95", math.nan) for s in sigmas]
        ax.errorbar(
            sigmas,
            means,
            yerr=np.nan_to_num(cis),
            marker="o",
            capsize=3,
            label=f"{method_label(str(r['method']))} {r['formation']} n={r.get('n', '?')}",
        )
    ax.set_xscale("log")
    ax.set_xlabel("sigma (m)")
    ax.set_ylabel("CFI (%)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig
