"""Using a trained deep graph cut: subteam probabilities, hard subteams, and the number of subteams to ask for."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from stafpipe.highlevel.config import HighLevelConfig
from stafpipe.highlevel.graphs import Team, TeamGraph, collate, node_features, radius_adjacency, team_graph
from stafpipe.highlevel.model import DeepGraphCut, NumpyGraphCut, softmax_rows
from stafpipe.highlevel.partition import choose_m, connected_subteams, hard_assignment

SMALL_TEAM = 64
"""A single team up to this size is decided by the numpy forward pass (same output, a fraction of the time)."""


def predict(model: DeepGraphCut, teams: Sequence[Team]) -> list[np.ndarray]:
    """Y (n, m_max) of each team (rows sum to 1 over its first m columns)."""
    cfg = model.cfg
    return _predict(model, teams, [team_graph(t, cfg.features, cfg.radius) for t in teams])


def _predict(
    model: DeepGraphCut, teams: Sequence[Team], graphs: list[TeamGraph], fast: NumpyGraphCut | None = None
) -> list[np.ndarray]:
    """`fast`: the model's numpy copy when the caller keeps one (the weights are copied per call otherwise)."""
    cfg = model.cfg
    if len(teams) == 1 and teams[0].n <= SMALL_TEAM:
        return [
            (fast if fast is not None else NumpyGraphCut(model))(
                graphs[0].x, graphs[0].edges, min(teams[0].m, cfg.m_max)
            )
        ]
    with torch.no_grad():
        y = model(collate(graphs, [min(t.m, cfg.m_max) for t in teams])).numpy()
    bounds = np.cumsum([0] + [t.n for t in teams])
    return [y[bounds[k] : bounds[k + 1]] for k in range(len(teams))]


def divide(model: DeepGraphCut, teams: Sequence[Team], fast: NumpyGraphCut | None = None) -> list[np.ndarray]:
    """Subteam label (0 .. m-1) of every robot of each team: argmax of Y, repaired (non-empty, connected where
    possible)."""
    cfg = model.cfg
    graphs = [team_graph(t, cfg.features, cfg.radius) for t in teams]
    out = []
    for team, graph, y in zip(teams, graphs, _predict(model, teams, graphs, fast), strict=True):
        if team.m <= 1:
            out.append(np.zeros(team.n, dtype=int))
            continue
        out.append(hard_assignment(y, graph.edges, min(team.m, cfg.m_max)))
    return out


def subteams_wanted(
    cfg: HighLevelConfig, kind: str, n: int, eta: float, robot_radius: float, angle_deg: float = 90.0
) -> int:
    """`high.m`: a fixed number, or with `auto` the smallest m whose subteams fit the passage width eta."""
    if cfg.m != "auto":
        return min(int(cfg.m), max(1, n - 1))
    m, _ = choose_m(kind, n, eta, robot_radius, cfg.safe_gap, min(cfg.m_max, max(1, n - 1)), angle_deg)
    return m


def small_team_features(team: Team, features: Sequence[str]) -> np.ndarray:
    """`node_features(team, features)`, the same values (a test), for the plan's split: the same sums, divisions and
    square root without numpy's wrappers (np.mean's sum and division, np.linalg.norm's dot product and root), written
    into one array rather than concatenated. Training keeps `node_features` itself: its arrays' places in memory are
    part of the graph cut's recorded rounding (graphs.py)."""
    if any(name not in ("pos", "goal", "heading") for name in features):
        return node_features(team, features)
    n = len(team.pos)
    centre, goal_centre = team.pos.sum(axis=0) / n, team.goal.sum(axis=0) / n
    d = goal_centre - centre
    x = np.empty((n, 2 * len(features)))
    for k, name in enumerate(features):
        col = x[:, 2 * k : 2 * k + 2]
        if name == "heading":
            col[:] = d / max(math.sqrt(float(d.dot(d))), 1e-9)
        elif name == "pos":
            np.subtract(team.pos, centre, out=col)
        else:
            np.subtract(team.goal, goal_centre, out=col)
    return x


def divider(checkpoint: str = ""):
    """`divide(pos, goal, m) -> labels` with the deep graph cut of `checkpoint` (empty: the shipped one), for STAF's
    plan (controllers/staf_plan.py)."""
    from stafpipe.highlevel.checkpoint import load_checkpoint

    model, _ = load_checkpoint(checkpoint)
    fast = NumpyGraphCut(model)  # the loaded weights never change: copy them once, not at every split

    def divide_team(pos: np.ndarray, goal: np.ndarray, m: int) -> np.ndarray:
        team = Team(np.asarray(pos, float), np.asarray(goal, float), m)
        if team.n > SMALL_TEAM or m <= 1:
            return divide(model, [team], fast)[0]
        # one small team, as `divide` decides it, on a dense radius graph: the step that splits stays within the
        # decision-time budget (benchmarks/staf_decision_time.py); a test checks both give the same labels
        adj = radius_adjacency(team.pos, model.cfg.radius)
        m = min(m, model.cfg.m_max)
        x = small_team_features(team, model.cfg.features)
        logits = fast.logits(x, np.zeros((2, 0), dtype=np.int64), m, adj=adj)
        labels, edges = logits[:, :m].argmax(axis=1), np.array(np.nonzero(adj))  # Y's argmax: softmax keeps order
        if connected_subteams(labels, edges, m):  # nothing for `repair` to change: no Y needed
            return labels
        return hard_assignment(softmax_rows(logits, m), edges, m)

    return divide_team
