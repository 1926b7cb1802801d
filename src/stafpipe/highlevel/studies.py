"""The graph-cut studies behind `stafpipe ablate`: each returns per-team rows, a summary, and example partitions.

loss_terms    STAF Fig. 7 (Section 5): one network per loss variant, 12 robots, 3 subteams.
subteam_count STAF Fig. 9: m = 2, 3, 4 on circle, wedge and line teams.
noise         STAF Fig. 14 (Appendix F): Gaussian noise on positions; agreement with the noise-free cut (adjusted Rand).
classical     Ours: the learned cut against spectral clustering and balanced k-means on the same teams.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats
from sklearn.metrics import adjusted_rand_score

from stafpipe.config.schema import DataConfig, FormationConfig
from stafpipe.highlevel.config import LOSS_VARIANTS, AblateConfig, HighLevelConfig, LossWeights, TrainHighConfig
from stafpipe.highlevel.graphs import Team, radius_edges, team_graph, teams_from_frame
from stafpipe.highlevel.infer import divide, predict
from stafpipe.highlevel.instances import generate_instances
from stafpipe.highlevel.model import DeepGraphCut
from stafpipe.highlevel.partition import balanced_kmeans, partition_stats, spectral_partition

TEST_STREAM = 1_000_003  # test teams are drawn from seed + TEST_STREAM * (k + 1): never the training draws


def draw_teams(kind: str, n: int, m: int, count: int, seed: int) -> list[Team]:
    """`count` synthetic teams as `stafpipe generate` makes them (docs/data.md), all of size n, cut into m."""
    df = generate_instances(DataConfig(instances=count, n_min=n, n_max=n), FormationConfig(type=kind), seed)
    return teams_from_frame(df, m)


def summarise(df: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    """Mean and 95 % confidence half-width (Student t) of every numeric column, per group."""
    rows = []
    value_cols = [c for c in df.columns if c not in by and c != "team" and pd.api.types.is_numeric_dtype(df[c])]
    for key, g in df.groupby(by, sort=False):
        row = dict(zip(by, key if isinstance(key, tuple) else (key,), strict=True))
        for c in value_cols:
            x = g[c].to_numpy(float)
            row[c] = float(x.mean())
            row[f"{c}_ci95"] = (
                float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))) if len(x) > 1 else math.nan
            )
        row["teams"] = len(g)
        rows.append(row)
    return pd.DataFrame(rows)


def _rows(
    partitions: list[np.ndarray], teams: list[Team], subteams: int, radius: float, **keys: Any
) -> list[dict[str, Any]]:
    return [
        {**keys, "team": k, **partition_stats(lab, t.pos, t.goal, radius_edges(t.pos, radius), subteams)}
        for k, (lab, t) in enumerate(zip(partitions, teams, strict=True))
    ]


def _example(team: Team, labels: np.ndarray, panel: str) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "panel": panel,
            "robot": np.arange(team.n),
            "x": team.pos[:, 0],
            "y": team.pos[:, 1],
            "goal_x": team.goal[:, 0],
            "goal_y": team.goal[:, 1],
            "subteam": labels,
        }
    )


def raw_labels(model: DeepGraphCut, teams: list[Team]) -> list[np.ndarray]:
    """argmax of Y without repair: what the network itself outputs (the ablation judges this)."""
    return [y[:, : t.m].argmax(axis=1) for t, y in zip(teams, predict(model, teams), strict=True)]


def loss_terms_study(
    ab: AblateConfig, high: HighLevelConfig, tc: TrainHighConfig, seed: int, out_dir: Path, config_hash: str
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Train one network per loss variant on n-robot teams, judge each on the same test teams (raw and repaired)."""
    from stafpipe.highlevel.training import train

    train_teams = draw_teams(ab.formation, ab.n, ab.m, ab.train_instances, seed)
    graphs = [team_graph(t, high.features, high.radius) for t in train_teams]
    test = draw_teams(ab.formation, ab.n, ab.m, ab.teams, seed + TEST_STREAM)
    rows, examples = [], []
    for variant in ab.variants:
        weights = LOSS_VARIANTS[variant]
        loss = tc.loss if weights is None else LossWeights(*weights)
        tcv = dataclasses.replace(tc, epochs=ab.epochs, m_choices=[ab.m], loss=loss, val_fraction=0.0)
        model, _ = train(
            graphs,
            high,
            tcv,
            seed,
            out_dir / "variants" / variant,
            f"{config_hash}/{variant}",
            {"study": "loss_terms", "variant": variant},
        )
        raw = raw_labels(model, test)
        rows += _rows(raw, test, ab.m, high.radius, variant=variant, labels="raw")
        rows += _rows(divide(model, test), test, ab.m, high.radius, variant=variant, labels="repaired")
        examples.append(_example(test[0], raw[0], variant))
    return pd.DataFrame(rows), pd.concat(examples, ignore_index=True)


def subteam_count_study(model: DeepGraphCut, ab: AblateConfig, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    rows, examples = [], []
    for k, kind in enumerate(ab.formations):
        for m in ab.m_values:
            teams = draw_teams(kind, ab.team_size, m, ab.teams, seed + TEST_STREAM * (k + 1))
            labels = divide(model, teams)
            rows += _rows(labels, teams, m, model.cfg.radius, formation=kind, m=m)
            examples.append(_example(teams[0], labels[0], f"{kind}, m={m}"))
    return pd.DataFrame(rows), pd.concat(examples, ignore_index=True)


def noise_study(model: DeepGraphCut, ab: AblateConfig, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Adjusted Rand index between the cut of noisy positions and the noise-free cut, per team and sigma."""
    teams = draw_teams(ab.formation, ab.n, ab.noise_m, ab.teams, seed + TEST_STREAM)
    clean = divide(model, teams)
    rows, examples = [], []
    for s, sigma in enumerate(ab.noise_sigmas):
        rng = np.random.default_rng([seed, 7, s])
        noisy = [dataclasses.replace(t, pos=t.pos + rng.normal(0.0, sigma, t.pos.shape)) for t in teams]
        labels = divide(model, noisy)
        for k, (t, lab, ref) in enumerate(zip(noisy, labels, clean, strict=True)):
            st = partition_stats(lab, t.pos, t.goal, radius_edges(t.pos, model.cfg.radius), ab.noise_m)
            rows.append({"sigma": sigma, "team": k, "ari": adjusted_rand_score(ref, lab), **st})
        examples.append(_example(noisy[0], labels[0], f"sigma={sigma:g}"))
    return pd.DataFrame(rows), pd.concat(examples, ignore_index=True)


def classical_study(model: DeepGraphCut, ab: AblateConfig, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The learned cut, spectral clustering and balanced k-means on the same teams, with time per team."""
    radius = model.cfg.radius
    methods = {
        "learned": lambda teams, m: divide(model, teams),
        "spectral": lambda teams, m: [
            spectral_partition(t.pos, t.goal, radius_edges(t.pos, radius), m, radius, seed) for t in teams
        ],
        "balanced_kmeans": lambda teams, m: [balanced_kmeans(t.pos, t.goal, m, seed) for t in teams],
    }
    rows, examples = [], []
    for k, kind in enumerate(ab.formations):
        for m in ab.m_values:
            teams = draw_teams(kind, ab.team_size, m, ab.teams, seed + TEST_STREAM * (k + 1))
            for name, fn in methods.items():
                start = time.perf_counter()
                labels = fn(teams, m)
                ms = 1000 * (time.perf_counter() - start) / len(teams)
                rows += [
                    {**r, "ms_per_team": ms} for r in _rows(labels, teams, m, radius, formation=kind, m=m, method=name)
                ]
                if m == ab.m_values[0]:
                    examples.append(_example(teams[0], labels[0], f"{kind}, {name}"))
    return pd.DataFrame(rows), pd.concat(examples, ignore_index=True)


FINDINGS = [  # STAF Section 5 on Fig. 7, as checks on the raw (unrepaired) partitions' means
    ("a_balance_only", "splits evenly", lambda s, full: s["imbalance"] <= 1.0),
    ("b_adjacency_only", "puts everyone in one subteam", lambda s, full: s["subteams_used"] <= 1.1),
    (
        "c_goal_only",
        "aligns subteams with goals (goal distance < full's)",
        lambda s, full: s["goal_distance"] < full["goal_distance"] - 1e-3,
    ),
    ("d_without_balance", "is unbalanced (imbalance > full's)", lambda s, full: s["imbalance"] > full["imbalance"]),
    (
        "e_without_adjacency",
        "is not compact (cut fraction > full's)",
        lambda s, full: s["cut_fraction"] > full["cut_fraction"],
    ),
    (
        "f_without_goal",
        "is misaligned with goals (goal distance > full's)",
        lambda s, full: s["goal_distance"] > full["goal_distance"] + 1e-3,
    ),
]


def findings_markdown(summary: pd.DataFrame) -> str:
    """The paper's qualitative findings on Fig. 7 checked against our numbers, as a Markdown table."""
    raw = summary[summary["labels"] == "raw"].set_index("variant")
    lines = [
        "| variant | the paper says it | holds here? | imbalance | subteams used | cut fraction | goal distance |",
        "|---|---|---|---|---|---|---|",
    ]
    if "full" not in raw.index:
        return "The `full` variant was not run; findings compare against it.\n"
    full = raw.loc["full"]
    for variant, claim, test in FINDINGS:
        if variant in raw.index:
            s = raw.loc[variant]
            lines.append(
                f"| {variant} | {claim} | {'yes' if test(s, full) else 'no'} | {s['imbalance']:.2f} | "
                f"{s['subteams_used']:.2f} | {s['cut_fraction']:.3f} | {s['goal_distance']:.3f} |"
            )
    lines.append(
        f"| full | (reference) | | {full['imbalance']:.2f} | {full['subteams_used']:.2f} | "
        f"{full['cut_fraction']:.3f} | {full['goal_distance']:.3f} |"
    )
    return "\n".join(lines) + "\n"
