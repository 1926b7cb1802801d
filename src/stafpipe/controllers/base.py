"""The one controller interface every method implements (straight, lf, zhu, cezayirli, dgnn, staf_planned).

Evaluation, metrics and logging never special-case a method: they call `reset_worlds` with one team per world of a
batch, then `act_worlds` once per control step on the batch's (B, n, ...) observations, and read each world's
`subteams`, `targets`, drained `events` and `episode_stats` through `world_view(w)`. A method written for one world
implements `reset` and `act`; the base class runs one copy of it per world. A method that gains from the batch (the
learned ones: features and plans of every world in one pass) overrides the three batch methods.
"""

from __future__ import annotations

import copy
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
    _worlds: list[Controller] = field(default_factory=list)
    """One copy per world of the batch (`reset_worlds`)."""

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

    def reset_worlds(self, teams: list[TeamInfo]) -> None:
        """Start an episode in each of B worlds (one team each). By default one copy of this controller per world,
        each reset as `reset` would."""
        template = copy.copy(self)
        template._worlds = []  # the copies do not nest the batch
        self._worlds = [copy.deepcopy(template) for _ in teams]
        for controller, team in zip(self._worlds, teams, strict=True):
            controller.reset(team)

    def act_worlds(self, obs: Observation, active: np.ndarray) -> np.ndarray:
        """Commanded planar velocities (B, n, 2) for a batch's observations; worlds whose `active` entry is false (their
        episode is over) get zeros and are not asked."""
        out = np.zeros(obs.position.shape)
        for w in np.flatnonzero(active).tolist():
            out[w] = self._worlds[w].act(obs.world(w))
        return out

    def world_view(self, w: int) -> Controller:
        """What the controller of world w reports: `subteams`, `targets`, `drain_events()`, `episode_stats()`."""
        return self._worlds[w]


STOP_GAP = 0.02
"""m: the surface gap at which `limit_approach` lets no more approach."""


def limit_approach(
    v: np.ndarray,
    obs: Observation,
    radius: float,
    avoid_distance: float,
    avoid_gain: float,
    stop_gap: float = STOP_GAP,
) -> np.ndarray:
    """Collision avoidance shared by the classical methods: towards any robot or obstacle closer than `avoid_distance`
    (surface to surface), the approach speed is capped at avoid_gain x (gap - stop_gap), so robots slide along and
    stop short of contact. `v` (.., n, 2) and `obs` of one world or of a batch of them (the same leading shape)."""
    v = np.array(v, dtype=float)
    rel = obs.rel_position  # [i, j] = p_j - p_i
    dist = np.linalg.norm(rel, axis=-1)
    gaps = dist - 2 * radius
    close = obs.neighbours & (gaps < avoid_distance)
    near_wall = obs.obstacle_distance < avoid_distance
    if not (close.any() or near_wall.any()):
        return v
    unit = rel / np.maximum(dist, 1e-9)[..., None]
    o_dir = obs.obstacle / np.maximum(np.linalg.norm(obs.obstacle, axis=-1, keepdims=True), 1e-9)
    # each robot's caps in this order: robots by index, then the wall; all robots (and worlds) at once, one cap each
    # step. The dot product as a stacked matmul: bit for bit what `v[i] @ n` gives for one robot (numpy's 1-D dot
    # fuses the multiply-add; an elementwise sum does not), so results do not depend on how many worlds are batched
    for normal, gap, active in [(unit[..., j, :], gaps[..., j], close[..., j]) for j in range(close.shape[-1])] + [
        (o_dir, obs.obstacle_distance, near_wall)
    ]:
        if not active.any():
            continue
        excess = (v[..., None, :] @ normal[..., :, None])[..., 0, 0] - avoid_gain * (gap - stop_gap)
        cut = active & (excess > 0)
        v = np.where(cut[..., None], v - excess[..., None] * normal, v)
    return v


MIN_COMMAND_SCALE = 1e-3
"""The smallest factor `forward_capped` scales a command by: the drive turns towards any command above 1e-6 m/s, so a
robot whose forward motion is capped to nothing still turns round towards its aim instead of standing pointed at
its neighbour."""


def forward_capped(
    world: np.ndarray,
    obs: Observation,
    radius: float,
    avoid_distance: float,
    avoid_gain: float,
    stop_gap: float = STOP_GAP,
) -> np.ndarray:
    """World-frame commands (B, n, 2) of differential-drive robots scaled down so that the motion the drive makes
    from them, forward along the heading at |command| x max(cos(heading error), 0) (drives.diff_drive), keeps the
    approach cap of `limit_approach` (avoid_gain x (gap - stop_gap) within avoid_distance) towards every sensed robot
    and the closest obstacle; the direction, and so the turn, is kept."""
    heading = np.stack([np.cos(obs.heading), np.sin(obs.heading)], axis=-1)
    forward = np.maximum((world * heading).sum(-1), 0.0)  # |command| x max(cos(error), 0)
    dist = np.linalg.norm(obs.rel_position, axis=-1)
    n = dist.shape[-1]
    gaps = np.where(obs.neighbours & ~np.eye(n, dtype=bool), dist - 2 * radius, np.inf)
    closing = (obs.rel_position * heading[..., None, :]).sum(-1) / np.maximum(dist, 1e-9)  # cos(heading, bearing)
    wall_closing = (obs.obstacle * heading).sum(-1) / np.maximum(np.linalg.norm(obs.obstacle, axis=-1), 1e-9)
    allowed = np.concatenate([gaps, obs.obstacle_distance[..., None]], axis=-1)
    cosine = np.concatenate([closing, wall_closing[..., None]], axis=-1)
    limit = np.where(
        (allowed < avoid_distance) & (cosine > 1e-9),
        np.maximum(avoid_gain * (allowed - stop_gap), 0.0) / np.maximum(cosine, 1e-9),
        np.inf,
    ).min(-1)  # the forward speed at which the closest-closing constraint is met exactly
    scale = np.where(forward > limit, np.maximum(limit / np.maximum(forward, 1e-9), MIN_COMMAND_SCALE), 1.0)
    return world * scale[..., None]
