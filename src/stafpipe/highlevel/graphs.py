"""Teams as graphs, batched in the sparse (edge-list) form: many teams of different sizes are one disjoint graph.

STAF Section 3: nodes are robots with attributes p_i (position), g_i (goal), q_i (velocity); a_ij = 1 when robots i and
j are within a radius (Appendix C: 2 m). A batch concatenates teams' nodes; `team[k]` says which team node k belongs to,
so no padding or masks are needed and a team's result does not depend on the other teams in its batch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import torch
from scipy.spatial import cKDTree

from stafpipe.highlevel.config import NODE_FEATURES

if TYPE_CHECKING:
    import pandas as pd


@dataclass
class Team:
    """One team: start positions (n, 2), goals (n, 2), velocities (n, 2) and the number of subteams wanted."""

    pos: np.ndarray
    goal: np.ndarray
    m: int
    vel: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.pos)


class TeamBatch(NamedTuple):
    """Disjoint union of teams; node tensors are (N, ...), N the total number of robots."""

    x: torch.Tensor
    """(N, F) node features."""
    pos: torch.Tensor
    """(N, 2) positions (for the loss)."""
    goal: torch.Tensor
    """(N, 2) goals (for the loss)."""
    edges: torch.Tensor
    """(2, E) long: directed edges src -> dst, both directions of every radius-graph pair, no self loops."""
    team: torch.Tensor
    """(N,) long: team index of each node."""
    m: torch.Tensor
    """(T,) long: subteams wanted per team."""
    sizes: torch.Tensor
    """(T,) long: robots per team."""

    def to(self, device: torch.device) -> TeamBatch:
        """The same batch on `device` (train_high.device)."""
        return TeamBatch(*(t.to(device) for t in self))


def radius_edges(pos: np.ndarray, radius: float) -> np.ndarray:
    """(2, E) directed edges between robots closer than `radius` (STAF's a_ij = 1), a KD-tree query (scales to
    1,000s)."""
    pairs = cKDTree(pos).query_pairs(radius, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((2, 0), dtype=np.int64)
    return np.concatenate([pairs.T, pairs[:, ::-1].T], axis=1).astype(np.int64)


def radius_adjacency(pos: np.ndarray, radius: float) -> np.ndarray:
    """(n, n) bool: robots closer than `radius`, no self loops; `radius_edges` as a dense matrix, for small teams
    (a KD-tree's setup costs more than all n^2 distances of ten robots)."""
    gap = pos[:, None, :] - pos[None, :, :]
    adj = np.einsum("ijk,ijk->ij", gap, gap) <= radius * radius
    adj.flat[:: len(pos) + 1] = False  # np.fill_diagonal's own assignment, without its checks (every plan step)
    return adj


def node_features(team: Team, features: Sequence[str]) -> np.ndarray:
    """(n, F) node features of one team, in the order `features` names them (see NODE_FEATURES). Columns built apart
    and concatenated: filling one array in place gave the same values but moved where later arrays lie in memory, and
    the graph cut's training then rounded differently (docs/reproduction.md)."""
    centre, goal_centre = team.pos.mean(axis=0), team.goal.mean(axis=0)
    cols = []
    for name in features:
        if name == "pos":
            cols.append(team.pos - centre)
        elif name == "goal":
            cols.append(team.goal - goal_centre)
        elif name == "heading":
            d = goal_centre - centre
            cols.append(np.broadcast_to(d / max(float(np.linalg.norm(d)), 1e-9), team.pos.shape))
        elif name == "vel":
            cols.append(team.vel if team.vel is not None else np.zeros_like(team.pos))
        else:
            raise ValueError(f"unknown node feature {name!r}; known: {list(NODE_FEATURES)}")
    return np.concatenate(cols, axis=1)


class TeamGraph(NamedTuple):
    """One team's graph, computed once and reused by every batch it goes into."""

    x: np.ndarray
    pos: np.ndarray
    goal: np.ndarray
    edges: np.ndarray


def team_graph(team: Team, features: Sequence[str], radius: float) -> TeamGraph:
    """Node features and radius-graph edges of one team."""
    return TeamGraph(node_features(team, features), team.pos, team.goal, radius_edges(team.pos, radius))


def collate(graphs: Sequence[TeamGraph], m: Sequence[int]) -> TeamBatch:
    """Stack team graphs into one disjoint graph; `m[k]` subteams are wanted of team k."""
    sizes_np = np.array([len(g.pos) for g in graphs])
    offsets = np.concatenate([[0], np.cumsum(sizes_np)[:-1]])
    sizes = torch.from_numpy(sizes_np).long()
    return TeamBatch(
        x=torch.from_numpy(np.concatenate([g.x for g in graphs])).float(),
        pos=torch.from_numpy(np.concatenate([g.pos for g in graphs])).float(),
        goal=torch.from_numpy(np.concatenate([g.goal for g in graphs])).float(),
        edges=torch.from_numpy(np.concatenate([g.edges + o for g, o in zip(graphs, offsets, strict=True)], axis=1)),
        team=torch.repeat_interleave(torch.arange(len(graphs)), sizes),
        m=torch.tensor(list(m), dtype=torch.long),
        sizes=sizes,
    )


def make_batch(teams: Sequence[Team], features: Sequence[str], radius: float) -> TeamBatch:
    """Stack teams into one disjoint graph."""
    return collate([team_graph(t, features, radius) for t in teams], [t.m for t in teams])


def teams_from_frame(df: pd.DataFrame, m: int | Sequence[int], rng: np.random.Generator | None = None) -> list[Team]:
    """Teams of a `stafpipe generate` table (docs/data.md); `m` fixed, or drawn per team from a list with `rng`."""
    teams = []
    for _, g in df.sort_values(["instance", "robot"]).groupby("instance", sort=True):
        pos = g[["x", "y"]].to_numpy(float)
        goal = g[["goal_x", "goal_y"]].to_numpy(float)
        mm = m if isinstance(m, int) else int(m[int(rng.integers(len(m)))]) if rng is not None else int(m[0])
        teams.append(Team(pos, goal, max(1, min(mm, len(pos) - 1))))  # STAF Section 3: m < n
    return teams
