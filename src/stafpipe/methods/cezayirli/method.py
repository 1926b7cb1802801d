"""`method=cezayirli`: non-communicating robots with switchable formations (Cezayirli and Kerestecioglu, "A
Non-Communicating Multi-Robot System with Switchable Formations"). Robots have no IDs and no communication; each sees
the robots within d_max (sensing.radius)
with bounded range and bearing errors (sensing.range_error, sensing.bearing_error_deg) and occlusion
(sensing.occlusion).

Local Steering Strategy (Section III, Fig. 2): a follower steps towards the minimiser of its cost J by the gradient step
(11), x_i(t + dt) = -gamma grad J at its own position (local coordinates, robot at the origin); the leader steps along
its trajectory at the physical limit. Every robot, leader included, then takes the largest step along that direction
that satisfies Theorem 1:
  (1)  ||x_i(t+dt)|| <= (d_m - max_{p in S_ip} ||x_p||) / 2,     S_ip: sensed robots with x_i(t+dt)^T x_p <= 0
  (2)  ||x_i(t+dt)||^2 <= min_{q in S_iq} x_i(t+dt)^T x_q,        S_iq: sensed robots with x_i(t+dt)^T x_q > 0
with d_m = d_max - Delta r (the definition after Section II's sensing model), capped by the physical limit
(max speed x control period).
Costs: (5) max_k ||z_k||; (6) sum_k (||z_k|| - d_0)^2; line (10) = 1/2 ||z_a + d_1 e_l||^2 + beta sum_{k != a}
(||z_k|| - d_1)^2 with a = the nearest sensed robot with x_a^T e_l >= 0 (7); the V formation uses two line-up vectors
(Section V, simulation 2). z_k = x_i(t+dt) - x_k (3). Costs switch at pre-loaded locations (Section V).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stafpipe.controllers.base import Controller, TeamInfo
from stafpipe.errors import require
from stafpipe.sensing import Observation

COSTS = ("max", "spread", "line", "v")


@dataclass
class Switch:
    """At `at` (x, y), a robot that comes within `radius` switches to `cost` (Section V: pre-loaded locations)."""

    at: list[float] = field(default_factory=lambda: [0.0, 0.0])
    cost: str = "line"
    """max (5), spread (6), line (10), or v (two line-up vectors)."""
    direction_deg: float = 0.0
    """line: direction of the line-up vector e_l; v: the direction the V points to (its apex leads)."""
    radius: float = 5.0


@dataclass
class CezayirliConfig:
    """Config of `method=cezayirli` (group `method`). Defaults: the paper's simulation 1 where it gives values."""

    name: str = "cezayirli"
    d_max: float = 30.0
    """Sensor range (Section V: 30 units); must equal sensing.radius."""
    range_error: float = 0.9
    """Delta r (Section V: 0.03 d_max); d_m = d_max - Delta r. Must match sensing.range_error."""
    initial_cost: str = "spread"
    """The cost before any switch (simulation 1 starts with (6))."""
    d0: float = 8.0
    """Desired distance in (6); the paper gives none (d_0 < d_m)."""
    d1: float = 4.0
    """Line spacing in (7)/(10); the paper gives none (d_1 < d_m)."""
    beta: float = 0.1
    """Weight of the other neighbours in (10) (beta > 0; no value given)."""
    gamma: float = 0.2
    """Gradient gain in (11) (gamma > 0; no value given)."""
    v_angle_deg: float = 120.0
    """Apex angle of the V (simulation 2: 120 degrees)."""
    period: float = 0.1
    """Delta t, the sensing/steering period (s): must equal world.control_dt (one step per control period)."""
    leader_speed: float = 1.0
    """The leader's step as a fraction of the physical limit (Fig. 2: the limit, 1.0)."""
    v_ahead_only: bool = True
    """Ours: in the V, a robot lines up only behind robots that are also ahead along the V's course. Without it a
    robot of one arm picks a robot of the other arm level with it as R_a and the two chase each other (docs)."""
    body_gap: float = 0.2
    """Ours: a step also stops this far short of touching a robot ahead (the paper's robots are points for motion)."""
    switches: list[Switch] = field(default_factory=list)

    def check(self, key: str = "method") -> None:
        require(
            self.d_max > self.range_error > 0,
            f"{key}.d_max/range_error",
            "need d_max > range_error > 0",
            (self.d_max, self.range_error),
        )
        d_m = self.d_max - self.range_error
        require(
            0 < self.d0 < d_m and 0 < self.d1 < d_m,
            f"{key}.d0/d1",
            f"must be in (0, d_m = {d_m:g})",
            (self.d0, self.d1),
        )
        require(self.period > 0, f"{key}.period", "must be > 0", self.period)
        require(self.beta > 0 and self.gamma > 0, f"{key}.beta/gamma", "must be > 0", (self.beta, self.gamma))
        for s in [self.initial_cost, *[w.cost for w in self.switches]]:
            require(s in COSTS, f"{key}.switches", f"costs must be in {list(COSTS)}", s)

    def check_run(self, sensing: Any, world: Any, key: str = "method") -> None:
        """The robots' sensor is the run's (Section II): d_max = sensing.radius, Delta r = sensing.range_error, and one
        steering step per control period."""
        for mine, theirs, name, other in (
            (self.d_max, sensing.radius, "d_max", "sensing.radius"),
            (self.range_error, sensing.range_error, "range_error", "sensing.range_error"),
            (self.period, world.control_dt, "period", "world.control_dt"),
        ):
            hint = f"must be equal (the robots' sensor is the run's): set {key}.{name}={theirs:g} or {other}={mine:g}"
            require(math.isclose(mine, theirs), f"{key}.{name}/{other}", f"{hint}, or use experiment=cezayirli_sim1",
                    (mine, theirs))  # fmt: skip


def _unit(deg: float) -> np.ndarray:
    return np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])


def cost_gradient(
    x: np.ndarray, cost: str, cfg: CezayirliConfig, e_l: np.ndarray, course: np.ndarray | None = None
) -> np.ndarray:
    """grad J at the robot's own position (the origin), for sensed relative positions x (M, 2): z_k = -x_k.

    With `course` (the V's direction), a must also lie ahead along it (ours, see docs/cezayirli.md)."""
    if len(x) == 0:
        return np.zeros(2)
    z = -x
    dist = np.maximum(np.linalg.norm(z, axis=1), 1e-9)
    if cost == "max":  # (5): the gradient of max_k ||z_k|| is the unit z of the farthest
        k = int(dist.argmax())
        return z[k] / dist[k]
    if cost == "spread":  # (6)
        return (2 * (dist - cfg.d0) / dist) @ z
    ok = x @ e_l >= 0  # (7): a is the nearest robot with a non-negative projection on e_l
    if course is not None:
        ok &= x @ course > 0
    ahead = np.flatnonzero(ok)
    grad = np.zeros(2)
    others = np.ones(len(x), dtype=bool)
    if len(ahead):
        a = ahead[dist[ahead].argmin()]
        grad += z[a] + cfg.d1 * e_l  # d/dx of 1/2 ||z_a + d1 e_l||^2
        others[a] = False
    return grad + cfg.beta * ((2 * (dist[others] - cfg.d1) / dist[others]) @ z[others])  # (10)


def max_step(x: np.ndarray, u: np.ndarray, d_m: float, body: float) -> float:
    """The largest step along unit u allowed by Theorem 1's (1) and (2) (and ours: no step into a robot ahead)."""
    if len(x) == 0:
        return d_m / 2
    proj = x @ u
    behind = proj <= 0
    limit = 0.5 * (d_m - (np.linalg.norm(x[behind], axis=1).max() if behind.any() else 0.0))  # (1)
    if (~behind).any():
        limit = min(limit, float(proj[~behind].min()))  # (2): s^2 <= s u^T x_q for every q ahead
        lateral = np.abs(x[~behind] @ np.array([-u[1], u[0]]))
        in_way = lateral < body
        if in_way.any():  # ours: stop `body` short along the line of a robot that is in the way
            limit = min(limit, float((proj[~behind][in_way] - np.sqrt(body**2 - lateral[in_way] ** 2)).min()))
    return max(limit, 0.0)


class CezayirliController(Controller):
    """Local Steering Strategy for every robot of one world."""

    def __init__(self, cfg: CezayirliConfig) -> None:
        super().__init__()
        cfg.check()
        self.cfg = cfg

    def reset(self, team: TeamInfo) -> None:
        super().reset(team)
        spec = team.scenario.spec
        self.speed = spec.robot.max_speed  # the physical limit: a step is at most speed x period
        self.radius = spec.robot.radius
        heading = _unit(spec.team.heading_deg)
        self.leader = int(((team.start - team.start.mean(0)) @ heading).argmax())  # the robot in front
        self.trajectory = np.array([*spec.reference_path, team.goal[self.leader]], dtype=float).reshape(-1, 2)
        self.waypoint = 0
        self.cost = [self.cfg.initial_cost] * self.n
        self.direction = [0.0] * self.n
        self.next_switch = [0] * self.n
        self.side = np.zeros(self.n)  # for the V: +1 left arm, -1 right arm

    def _switch(self, i: int, p: np.ndarray) -> None:
        k = self.next_switch[i]
        if k < len(self.cfg.switches) and np.linalg.norm(p - self.cfg.switches[k].at) <= self.cfg.switches[k].radius:
            s = self.cfg.switches[k]
            self.cost[i], self.direction[i] = s.cost, s.direction_deg
            self.next_switch[i] = k + 1
            self.emit("switch", [i], f"cost={s.cost} direction_deg={s.direction_deg:g}")

    def act(self, obs: Observation) -> np.ndarray:
        cfg, p, dt = self.cfg, obs.position, self.cfg.period
        d_m = cfg.d_max - cfg.range_error
        limit = self.speed * dt
        steps = np.zeros_like(p)
        for i in range(self.n):
            x = obs.rel_position[i][obs.neighbours[i]]  # measured, errors and occlusion included
            if i == self.leader:
                while (
                    self.waypoint + 1 < len(self.trajectory)
                    and np.linalg.norm(self.trajectory[self.waypoint] - p[i]) < limit
                ):
                    self.waypoint += 1
                d = self.trajectory[self.waypoint] - p[i]
                size = min(cfg.leader_speed * limit, float(np.linalg.norm(d)))
            else:
                self._switch(i, p[i])
                e_l = self._line_up(i, p)
                course = _unit(self.direction[i]) if self.cost[i] == "v" and cfg.v_ahead_only else None
                d = -cost_gradient(x, self.cost[i], cfg, e_l, course)
                size = cfg.gamma * float(np.linalg.norm(d))  # (11)
            norm = float(np.linalg.norm(d))
            if norm < 1e-9:
                continue
            u = d / norm
            size = min(size, max_step(x, u, d_m, 2 * self.radius + cfg.body_gap), limit)
            steps[i] = u * size
        return steps / dt

    def _line_up(self, i: int, p: np.ndarray) -> np.ndarray:
        """e_l of robot i: the line direction, or for the V one of two arms (Section V, simulation 2)."""
        cost, heading = self.cost[i], self.direction[i]
        if cost != "v":
            return _unit(heading)
        if self.side[i] == 0:  # the arm is chosen once, by the side of the leader's course the robot is on
            course = _unit(heading)
            rel = p[i] - p[self.leader]
            self.side[i] = 1.0 if course[0] * rel[1] - course[1] * rel[0] >= 0 else -1.0
        # e_l points along the arm towards the apex: from the left arm forward-right, from the right arm forward-left
        return _unit(heading - self.side[i] * self.cfg.v_angle_deg / 2)
