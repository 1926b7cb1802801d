"""ORCA, optimal reciprocal collision avoidance (van den Berg, Guy, Lin and Manocha, "Reciprocal n-body collision
avoidance", ISRR 2011): each robot takes the velocity nearest its preferred one among those that avoid, for `horizon`
seconds, every neighbour taking half of the avoidance, every moving obstacle taking none, and the nearest static
obstacle point. Zhu et al. 2019 track their targets with an MPC local planner [22]; this is the reciprocal-velocity
local planner that stands in for it (docs/zhu.md).

Each constraint is a half-plane of velocities, a line (point, direction) whose left side is allowed; the velocity is
found by the 2D incremental linear program of the ORCA paper (Sec. 5.2), and when the half-planes leave nothing, by the
program that least violates them (its Sec. 5.3).
"""

from __future__ import annotations

import math

import numpy as np

from stafpipe.sensing import Observation

_EPS = 1e-9
Line = tuple[np.ndarray, np.ndarray]
"""A half-plane of velocities: (a point on its boundary, the boundary's direction); the left side is allowed."""


def _det(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _line(
    rel_p: np.ndarray, rel_v: np.ndarray, radius: float, horizon: float, dt: float, share: float, v_own: np.ndarray
):
    """The half-plane for one other body: rel_p its position relative to the robot, rel_v the robot's velocity relative
    to it, radius the sum of both radii (and a margin); `share` of the avoidance is the robot's (1/2: reciprocal)."""
    dist2 = float(rel_p @ rel_p)
    r2 = radius * radius
    if dist2 > r2:  # not touching: the velocity obstacle truncated at `horizon`
        w = rel_v - rel_p / horizon
        w2 = float(w @ w)
        dot = float(w @ rel_p)
        if dot < 0 and dot * dot > r2 * w2:  # nearest point on the truncation circle
            w_len = math.sqrt(w2)
            unit = w / max(w_len, _EPS)
            direction = np.array([unit[1], -unit[0]])
            u = (radius / horizon - w_len) * unit
        else:  # nearest point on a leg of the cone
            leg = math.sqrt(dist2 - r2)
            if _det(rel_p, w) > 0:
                direction = np.array([rel_p[0] * leg - rel_p[1] * radius, rel_p[0] * radius + rel_p[1] * leg]) / dist2
            else:
                direction = -np.array([rel_p[0] * leg + rel_p[1] * radius, -rel_p[0] * radius + rel_p[1] * leg]) / dist2
            u = float(rel_v @ direction) * direction - rel_v
    else:  # already touching: get apart within one control step
        w = rel_v - rel_p / dt
        w_len = math.sqrt(float(w @ w))
        unit = w / max(w_len, _EPS)
        direction = np.array([unit[1], -unit[0]])
        u = (radius / dt - w_len) * unit
    return v_own + share * u, direction


def _lp1(lines: list[Line], k: int, max_speed: float, pref: np.ndarray, direction_opt: bool) -> np.ndarray | None:
    """The best velocity on line k within the speed disc and the lines before k (None: there is none)."""
    point, direction = lines[k]
    dot = float(point @ direction)
    disc = dot * dot + max_speed * max_speed - float(point @ point)
    if disc < 0:
        return None
    sq = math.sqrt(disc)
    t_left, t_right = -dot - sq, -dot + sq
    for i in range(k):
        p_i, d_i = lines[i]
        denom = _det(direction, d_i)
        numer = _det(d_i, point - p_i)
        if abs(denom) <= _EPS:  # parallel
            if numer < 0:
                return None
            continue
        t = numer / denom
        if denom >= 0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return None
    if direction_opt:
        t = t_right if float(pref @ direction) > 0 else t_left
    else:
        t = min(max(float(direction @ (pref - point)), t_left), t_right)
    return point + t * direction


def _lp2(lines: list[Line], max_speed: float, pref: np.ndarray, direction_opt: bool) -> tuple[int, np.ndarray]:
    """The velocity nearest `pref` (or furthest along it, `direction_opt`) in the speed disc and every half-plane;
    returns (number of lines satisfied, velocity): a count short of len(lines) means infeasible from that line on."""
    if direction_opt:
        result = pref * max_speed
    elif float(pref @ pref) > max_speed * max_speed:
        result = pref / math.sqrt(float(pref @ pref)) * max_speed
    else:
        result = pref.copy()
    for k, (point, direction) in enumerate(lines):
        if _det(direction, point - result) > 0:  # on the wrong side of line k
            found = _lp1(lines, k, max_speed, pref, direction_opt)
            if found is None:
                return k, result
            result = found
    return len(lines), result


def _lp3(lines: list[Line], n_fixed: int, start: int, max_speed: float, result: np.ndarray) -> np.ndarray:
    """When the half-planes from `start` on leave no velocity: the one that violates them least (the first `n_fixed`,
    static obstacles, stay hard)."""
    distance = 0.0
    for k in range(start, len(lines)):
        point, direction = lines[k]
        if _det(direction, point - result) <= distance:
            continue
        projected = list(lines[:n_fixed])
        for i in range(n_fixed, k):
            p_i, d_i = lines[i]
            det = _det(direction, d_i)
            if abs(det) <= _EPS:
                if float(direction @ d_i) > 0:  # same direction: no constraint between them
                    continue
                p = 0.5 * (point + p_i)
            else:
                p = point + (_det(d_i, point - p_i) / det) * direction
            d = d_i - direction
            projected.append((p, d / max(math.hypot(d[0], d[1]), _EPS)))
        pref = np.array([-direction[1], direction[0]])
        count, candidate = _lp2(projected, max_speed, pref, True)
        if count == len(projected):
            result = candidate
        distance = _det(direction, point - result)
    return result


def orca_velocities(
    pref: np.ndarray,
    obs: Observation,
    radius: float,
    max_speed: float,
    horizon: float,
    dt: float,
    margin: float,
    mover_radius: np.ndarray | None = None,
) -> np.ndarray:
    """Collision-free velocities (n, 2) nearest the preferred ones `pref` (n, 2) for one world's observation: every
    sensed robot (reciprocal), every moving obstacle (the robot avoids alone) and the nearest static obstacle point
    (hard), with `margin` (m) added to every clearance."""
    out = np.empty_like(pref)
    v = obs.velocity
    mover_r = np.zeros(0) if mover_radius is None else np.asarray(mover_radius, dtype=float)
    movers = obs.movers[: len(mover_r)]
    for i in range(len(pref)):
        lines: list[Line] = []
        gap = float(obs.obstacle_distance[i]) - margin
        if gap < max_speed * horizon:  # the nearest obstacle point: approach it no faster than closes the gap in time
            normal = obs.obstacle[i] / max(float(np.linalg.norm(obs.obstacle[i])), _EPS)
            lines.append((normal * max(gap, 0.0) / horizon, np.array([-normal[1], normal[0]])))
        n_fixed = len(lines)
        for j in np.flatnonzero(obs.neighbours[i]):
            lines.append(
                _line(obs.rel_position[i, j], -obs.rel_velocity[i, j], 2 * radius + margin, horizon, dt, 0.5, v[i])
            )
        for k in range(len(movers)):
            rel_p = movers[k, :2] - obs.position[i]
            if float(np.linalg.norm(rel_p)) < max_speed * horizon * 2 + mover_r[k]:  # it can be reached in time
                lines.append(_line(rel_p, v[i] - movers[k, 2:], radius + mover_r[k] + margin, horizon, dt, 1.0, v[i]))
        count, result = _lp2(lines, max_speed, pref[i], False)
        if count < len(lines):
            result = _lp3(lines, n_fixed, count, max_speed, result)
        out[i] = result
    return out
