"""The one controller interface every method implements (straight, lf, zhu, cezayirli, dgnn, staf).

Evaluation, metrics and logging never special-case a method: they call `reset`, then `act` once per control step, and
read `subteams`, `targets` and the drained `events`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from stafpipe.scenario import Scenario
from stafpipe.sensing import Observation


@dataclass
class TeamInfo:
    """What a controller knows when an episode starts (STAF B.2: the map and the start and goal positions)."""

    scenario: Scenario
    start: np.ndarray
    """(n, 2) robots' start positions."""
    goal: np.ndarray
    """(n, 2) the team's goal slots; robot i's own goal is goal[i]."""
    template: np.ndarray
    """(n, 2) the formation's slots in its own frame (x ahead)."""
    path: np.ndarray
    """(K, 2) shortest collision-free path of the formation centre (geometry.Geometry.shortest_path)."""
    passage_width: float
    """Narrowest passage on the way (STAF's eta)."""


@dataclass
class Event:
    """Something a method decided: a split, a merge, a fault (collisions are logged by the harness)."""

    kind: str
    robots: list[int]
    detail: str = ""


@dataclass
class Controller:
    """Base class: a team of n robots driven by one method."""

    n: int = 0
    _subteams: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    _targets: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    _events: list[Event] = field(default_factory=list)

    def reset(self, team: TeamInfo) -> None:
        """Start an episode."""
        self.n = len(team.start)
        self._subteams = np.zeros(self.n, dtype=int)
        self._targets = team.goal.copy()
        self._events = []

    def act(self, obs: Observation) -> np.ndarray:
        """Commanded planar velocities (n, 2) for the observation of one world."""
        raise NotImplementedError

    @property
    def subteams(self) -> np.ndarray:
        """(n,) subteam id of each robot."""
        return self._subteams

    @property
    def targets(self) -> np.ndarray:
        """(n, 2) where each robot is heading now (its formation slot or goal)."""
        return self._targets

    def emit(self, kind: str, robots: list[int], detail: str = "") -> None:
        """Record an event for the log."""
        self._events.append(Event(kind, robots, detail))

    def episode_stats(self) -> dict[str, float]:
        """Method-specific numbers for the results table (e.g. Zhu's per-part computation times); none by default."""
        return {}

    def drain_events(self) -> list[Event]:
        """The events since the last call."""
        out, self._events = self._events, []
        return out


def limit_approach(
    v: np.ndarray, obs: Observation, radius: float, avoid_distance: float, avoid_gain: float, stop_gap: float = 0.02
) -> np.ndarray:
    """Collision avoidance shared by the classical methods: towards any robot or obstacle closer than `avoid_distance`
    (surface to surface), the approach speed is capped at avoid_gain x (gap - stop_gap), so robots slide along and
    stop short of contact."""
    v = v.copy()
    rel = obs.rel_position  # [i, j] = p_j - p_i
    dist = np.linalg.norm(rel, axis=-1)
    gaps = dist - 2 * radius
    close = obs.neighbours & (gaps < avoid_distance)
    o_dir = obs.obstacle / np.maximum(np.linalg.norm(obs.obstacle, axis=-1, keepdims=True), 1e-9)
    for i in range(len(v)):
        normals = [rel[i, j] / max(dist[i, j], 1e-9) for j in np.flatnonzero(close[i])]
        limits = [gaps[i, j] for j in np.flatnonzero(close[i])]
        if obs.obstacle_distance[i] < avoid_distance:
            normals.append(o_dir[i])
            limits.append(obs.obstacle_distance[i])
        for n_vec, gap in zip(normals, limits, strict=True):
            excess = float(v[i] @ n_vec) - avoid_gain * (gap - stop_gap)
            if excess > 0:
                v[i] -= excess * n_vec
    return v
