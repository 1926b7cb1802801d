"""`method=lf`: the leader-follower baseline STAF compares with (STAF Section 4, "L&F [15]": Reily, Reardon, Zhang,
RSS 2020): "one of the robots is designated as the leader robot that leads the movements of the other follower robots
in the team while maintaining the formation". No subteaming and no formation adaptation, by design.

Leader: the robot in the formation's front slot; it follows its own shortest collision-free path on the map (the
harness' grid planner, clearance = robot radius + `clearance_margin`) at a speed that drops while followers lag.
Followers: each tracks its slot = leader position + R(path heading) (slot_i - slot_leader), the formation rotated to the
direction the leader moves, with a proportional gain. Collision avoidance (`local_planner`): for holonomic robots
ORCA makes the control law's velocities collision-free (controllers/orca.py, as method=zhu's); for differential
drive, whose motion is not the velocity ORCA chose, the approach speed towards robots and obstacles closer than
`avoid_distance` is capped in proportion to the gap, on the command and on the motion the drive makes from it. Then
the drive caps the speed.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import cast

import numpy as np

from stafpipe.controllers.base import Controller, TeamInfo, forward_capped, limit_approach
from stafpipe.controllers.orca import ORCA_HORIZON, ORCA_MARGIN, ORCA_RECOVERY, avoid_movers, orca_velocities
from stafpipe.errors import require
from stafpipe.formations import rotation
from stafpipe.geometry import Geometry, path_parts, point_ahead
from stafpipe.sensing import Observation


@dataclass
class LFConfig:
    """Config of `method=lf` (group `method`)."""

    name: str = "lf"
    gain: float = 1.5
    """Proportional gain (1/s) of a follower towards its slot (and of the leader towards its path point)."""
    lookahead: float = 1.0
    """The leader steers to the point this far ahead on its path (m)."""
    lag_slowdown: float = 0.5
    """Leader speed factor = 1 / (1 + lag_slowdown x mean follower slot error in m): it waits for its team."""
    avoid_distance: float = 0.35
    """Surface gap (m) under which the approach speed towards a robot or an obstacle is limited."""
    avoid_gain: float = 2.0
    """Allowed approach speed (m/s) per metre of gap left (minus 0.02 m)."""
    clearance_margin: float = 0.1
    """Added to the robot radius as the leader path's clearance from obstacles (m)."""
    local_planner: str = "auto"
    """Collision avoidance: `orca` (ORCA, controllers/orca.py, with method=zhu's horizon 1 s, margin 0.1 m and
    recovery 0.1 s), `cap` (the approach cap above), `forward` (the cap, and on a
    differential drive the same cap on the motion the drive makes from the capped command, `base.forward_capped`), or
    `auto`: ORCA for holonomic robots, `forward` for differential drive.
    docs/baselines.md has them measured."""

    def check(self, key: str = "method") -> None:
        lp = self.local_planner
        planners = ("auto", "orca", "cap", "forward")
        require(lp in planners, f"{key}.local_planner", "must be auto, orca, cap or forward", lp)


class LFController(Controller):
    """Leader-follower formation control with collision avoidance."""

    def __init__(self, cfg: LFConfig) -> None:
        super().__init__()
        cfg.check()
        self.cfg = cfg

    def reset(self, team: TeamInfo) -> None:
        super().reset(team)
        spec = team.scenario.spec
        self.radius, self.max_speed = spec.robot.radius, spec.robot.max_speed
        self.forward = spec.robot.drive == "diff_drive" and self.cfg.local_planner in ("forward", "auto")
        self.orca = self.cfg.local_planner == "orca" or (
            self.cfg.local_planner == "auto" and spec.robot.drive == "holonomic"
        )
        self.mover_radius = np.array([m.radius for m in spec.moving_obstacles])  # ORCA avoids them too
        # slots in the team's frame, with robot i at slot i (the harness places robot i on slot i of the template)
        self.slots = team.template - team.template.mean(axis=0)
        self.leader = int(self.slots[:, 0].argmax())
        self.heading = math.radians(spec.team.heading_deg)
        # the leader's route: through the scenario's reference waypoints, as every method's team path goes (a route
        # that loops back to near its start, Zhu et al.'s Scenario 1, was otherwise cut to its last 0.5 m)
        route = [tuple(team.start[self.leader]), *map(tuple, spec.reference_path), tuple(team.goal[self.leader])]
        geometry, keep = Geometry.of(team.scenario), self.radius + self.cfg.clearance_margin
        try:
            legs = [geometry.path_to(a, b, keep) for a, b in itertools.pairwise(route)]
            self.path = np.concatenate([legs[0], *[leg[1:] for leg in legs[1:]]])
        except ValueError:  # no path with the margin: fall back to straight lines (it will get stuck, honestly)
            self.path = np.array(route, dtype=float)
        self.path_parts = path_parts(self.path)
        self.goal = team.goal
        self.lead_heard = np.array(team.start[self.leader], dtype=float)
        self.lead_arc = 0.0  # the leader's arc length along its path (`point_ahead`'s `near`)

    def act(self, obs: Observation) -> np.ndarray:
        v = self._command(obs)
        if self.orca:  # method=zhu's ORCA settings
            return orca_velocities(
                v,
                obs,
                self.radius,
                self.max_speed,
                ORCA_HORIZON,
                ORCA_RECOVERY,
                ORCA_MARGIN,
                self.mover_radius,
            )
        return self._capped(v[None], Observation(*(np.asarray(x)[None] for x in obs)))[0]

    def act_worlds(self, obs: Observation, active: np.ndarray) -> np.ndarray:
        """As `act` in every active world, the collision avoidance of all of them in one call (world by world it was
        a sixth of an L&F evaluation's time under cProfile; the same bits either way, `limit_approach`)."""
        out = np.zeros(obs.position.shape)
        worlds = np.flatnonzero(active)
        if not len(worlds):
            return out
        copies = [cast(LFController, self._worlds[w]) for w in worlds.tolist()]
        radii = {c.radius for c in copies}
        movers = {tuple(c.mover_radius.tolist()) for c in copies}
        if len(radii) > 1 or len(movers) > 1 or any(c.orca for c in copies):  # unlike worlds, or ORCA: one by one
            return super().act_worlds(obs, active)
        v = np.stack([c._command(obs.world(w)) for c, w in zip(copies, worlds.tolist(), strict=True)])
        batch = Observation(*(x[worlds] for x in obs))
        out[worlds] = copies[0]._capped(v, batch)  # the batch's robots are alike (one radius, one drive)
        return out

    def _capped(self, v: np.ndarray, obs: Observation) -> np.ndarray:
        """The approach cap on the control law's velocities (`limit_approach`) and, with `forward` (and `auto`) on a
        differential drive, on the motion the drive makes from them (`forward_capped`), the moving obstacles avoided
        first (`orca.avoid_movers`)."""
        cfg = self.cfg
        if len(self.mover_radius):  # walkers, as ORCA avoids them for holonomic robots (the batch shares one map)
            v = np.stack(
                [
                    avoid_movers(v[b], obs.world(b), self.radius, self.max_speed, self.mover_radius)
                    for b in range(len(v))
                ]
            )
        v = limit_approach(v, obs, self.radius, cfg.avoid_distance, cfg.avoid_gain)
        if self.forward:
            v = forward_capped(v, obs, self.radius, cfg.avoid_distance, cfg.avoid_gain)
        return v

    def _command(self, obs: Observation) -> np.ndarray:
        """The control law's velocities (n, 2) before collision avoidance."""
        cfg, p = self.cfg, obs.position
        # The leader broadcasts its position; the team relays it (range-free, as Reily et al.'s leader is followed by
        # all). When robots that sense the leader do not hear it (a silent leader, dropped messages: the world's
        # faults), the followers go on with the last position they received.
        others = np.arange(len(p)) != self.leader
        if obs.heard[others, self.leader].any() or not obs.neighbours[others, self.leader].any():
            self.lead_heard = p[self.leader].copy()
        lead = p[self.leader]  # the leader knows where it is
        # the leader's place on its path: near where it was a step before (a route that comes back near its start)
        points, directions, left = point_ahead(
            self.path, lead[None], cfg.lookahead, self.path_parts, near=np.array([self.lead_arc])
        )
        point, direction = points[0], directions[0]
        self.lead_arc = float(self.path_parts[2][-1] - left[0])
        to_goal = float(np.linalg.norm(self.goal[self.leader] - lead))
        end = left[0] <= cfg.lookahead  # near the goal at the route's end, not only near it in the plane
        if to_goal > cfg.lookahead or not end:
            self.heading = math.atan2(direction[1], direction[0])  # the formation turns with the leader's path
        slots = self.lead_heard + (self.slots - self.slots[self.leader]) @ rotation(self.heading).T
        at_goal = to_goal < 0.5 * cfg.lookahead and end
        if at_goal:  # the leader has arrived: everyone takes its own goal slot
            slots = self.goal
        v = cfg.gain * (slots - p)
        lag = float(np.delete(np.linalg.norm(slots - p, axis=1), self.leader).mean()) if len(p) > 1 else 0.0
        to_point = point - lead if not at_goal else self.goal[self.leader] - lead
        v[self.leader] = cfg.gain * to_point / (1.0 + cfg.lag_slowdown * lag)
        self._targets = slots.copy()
        self._targets[self.leader] = point
        return v
