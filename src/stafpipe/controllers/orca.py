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
# ORCA's settings as method=zhu, L&F and the `orca` teacher use them by default
ORCA_HORIZON = 1.0  # s: velocities keep every neighbour clear for this long
ORCA_MARGIN = 0.1  # m, added to the robots' and obstacles' radii
ORCA_RECOVERY = 0.1  # s in which two robots that touch are separated (the world's control period)
Vec = tuple[float, float]
Line = tuple[float, float, float, float]
"""A half-plane of velocities: a point on its boundary (px, py) and the boundary's direction (dx, dy); the left side
is allowed. Plain floats: a robot's program has a few dozen lines of two numbers each, where numpy's per-call cost
would be most of the work (the same operations in the same order, so the same bits)."""


def _line(rel_p: Vec, rel_v: Vec, radius: float, horizon: float, dt: float, share: float, v_own: Vec) -> Line:
    """The half-plane for one other body: rel_p its position relative to the robot, rel_v the robot's velocity relative
    to it, radius the sum of both radii (and a margin); `share` of the avoidance is the robot's (1/2: reciprocal)."""
    px, py = rel_p
    rvx, rvy = rel_v
    dist2 = px * px + py * py
    r2 = radius * radius
    if dist2 > r2:  # not touching: the velocity obstacle truncated at `horizon`
        wx, wy = rvx - px / horizon, rvy - py / horizon
        w2 = wx * wx + wy * wy
        dot = wx * px + wy * py
        if dot < 0 and dot * dot > r2 * w2:  # nearest point on the truncation circle
            w_len = math.sqrt(w2)
            scale = max(w_len, _EPS)
            ux, uy = wx / scale, wy / scale
            dx, dy = uy, -ux
            c = radius / horizon - w_len
            ox, oy = c * ux, c * uy
        else:  # nearest point on a leg of the cone
            leg = math.sqrt(dist2 - r2)
            if px * wy - py * wx > 0:
                dx, dy = (px * leg - py * radius) / dist2, (px * radius + py * leg) / dist2
            else:
                dx, dy = -((px * leg + py * radius) / dist2), -((-px * radius + py * leg) / dist2)
            c = rvx * dx + rvy * dy
            ox, oy = c * dx - rvx, c * dy - rvy
    else:  # already touching: get apart within one control step
        wx, wy = rvx - px / dt, rvy - py / dt
        w_len = math.sqrt(wx * wx + wy * wy)
        scale = max(w_len, _EPS)
        ux, uy = wx / scale, wy / scale
        dx, dy = uy, -ux
        c = radius / dt - w_len
        ox, oy = c * ux, c * uy
    return v_own[0] + share * ox, v_own[1] + share * oy, dx, dy


def _lp1(lines: list[Line], k: int, max_speed: float, pref: Vec, direction_opt: bool) -> Vec | None:
    """The best velocity on line k within the speed disc and the lines before k (None: there is none)."""
    px, py, dx, dy = lines[k]
    dot = px * dx + py * dy
    disc = dot * dot + max_speed * max_speed - (px * px + py * py)
    if disc < 0:
        return None
    sq = math.sqrt(disc)
    t_left, t_right = -dot - sq, -dot + sq
    for i in range(k):
        qx, qy, ex, ey = lines[i]
        denom = dx * ey - dy * ex
        numer = ex * (py - qy) - ey * (px - qx)
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
        t = t_right if pref[0] * dx + pref[1] * dy > 0 else t_left
    else:
        t = min(max(dx * (pref[0] - px) + dy * (pref[1] - py), t_left), t_right)
    return px + t * dx, py + t * dy


def _lp2(lines: list[Line], max_speed: float, pref: Vec, direction_opt: bool) -> tuple[int, Vec]:
    """The velocity nearest `pref` (or furthest along it, `direction_opt`) in the speed disc and every half-plane;
    returns (number of lines satisfied, velocity): a count short of len(lines) means infeasible from that line on."""
    pref2 = pref[0] * pref[0] + pref[1] * pref[1]
    if direction_opt:
        result = pref[0] * max_speed, pref[1] * max_speed
    elif pref2 > max_speed * max_speed:
        norm = math.sqrt(pref2)
        result = pref[0] / norm * max_speed, pref[1] / norm * max_speed
    else:
        result = pref
    for k, (px, py, dx, dy) in enumerate(lines):
        if dx * (py - result[1]) - dy * (px - result[0]) > 0:  # on the wrong side of line k
            found = _lp1(lines, k, max_speed, pref, direction_opt)
            if found is None:
                return k, result
            result = found
    return len(lines), result


def _lp3(lines: list[Line], n_fixed: int, start: int, max_speed: float, result: Vec) -> Vec:
    """When the half-planes from `start` on leave no velocity: the one that violates them least (the first `n_fixed`,
    static obstacles, stay hard)."""
    distance = 0.0
    for k in range(start, len(lines)):
        px, py, dx, dy = lines[k]
        if dx * (py - result[1]) - dy * (px - result[0]) <= distance:
            continue
        projected = list(lines[:n_fixed])
        for i in range(n_fixed, k):
            qx, qy, ex, ey = lines[i]
            det = dx * ey - dy * ex
            if abs(det) <= _EPS:
                if dx * ex + dy * ey > 0:  # same direction: no constraint between them
                    continue
                cx, cy = 0.5 * (px + qx), 0.5 * (py + qy)
            else:
                t = (ex * (py - qy) - ey * (px - qx)) / det
                cx, cy = px + t * dx, py + t * dy
            fx, fy = ex - dx, ey - dy
            scale = max(math.hypot(fx, fy), _EPS)
            projected.append((cx, cy, fx / scale, fy / scale))
        count, candidate = _lp2(projected, max_speed, (-dy, dx), True)
        if count == len(projected):
            result = candidate
        distance = dx * (py - result[1]) - dy * (px - result[0])
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
    n = len(pref)
    out = np.empty_like(pref)
    velocity = obs.velocity.tolist()
    obstacle = obs.obstacle.tolist()
    obstacle_distance = obs.obstacle_distance.tolist()
    prefs = pref.tolist()
    mover_r = [] if mover_radius is None else np.asarray(mover_radius, dtype=float).tolist()
    movers = obs.movers[: len(mover_r)].tolist()
    position = obs.position.tolist() if movers else []
    pair_radius = 2 * radius + margin
    rows, cols = np.nonzero(obs.neighbours)  # row by row, each row's neighbours in ascending order
    pair_p = obs.rel_position[rows, cols].tolist()
    pair_v = obs.rel_velocity[rows, cols].tolist()
    bounds = np.searchsorted(rows, np.arange(n + 1)).tolist()
    for i in range(n):
        lines: list[Line] = []
        v_own = velocity[i][0], velocity[i][1]
        wall = _wall_line(obstacle[i], obstacle_distance[i], margin, max_speed, horizon)
        if wall is not None:
            lines.append(wall)
        n_fixed = len(lines)
        for k in range(bounds[i], bounds[i + 1]):
            (qx, qy), (ux, uy) = pair_p[k], pair_v[k]
            lines.append(_line((qx, qy), (-ux, -uy), pair_radius, horizon, dt, 0.5, v_own))
        if movers:
            lines += _mover_lines(movers, mover_r, position[i], v_own, radius, max_speed, horizon, dt, margin)
        count, result = _lp2(lines, max_speed, (prefs[i][0], prefs[i][1]), False)
        if count < len(lines):
            result = _lp3(lines, n_fixed, count, max_speed, result)
        out[i] = result
    return out


def _wall_line(obstacle: list[float], distance: float, margin: float, max_speed: float, horizon: float) -> Line | None:
    """The half-plane of the nearest obstacle point (vector `obstacle` from the robot, surface gap `distance`):
    approach it no faster than closes the gap in `horizon`; None where it is too far to matter."""
    gap = distance - margin
    if gap >= max_speed * horizon:
        return None
    ax, ay = obstacle
    scale = max(math.sqrt(ax * ax + ay * ay), _EPS)
    nx, ny = ax / scale, ay / scale
    g = max(gap, 0.0)
    return nx * g / horizon, ny * g / horizon, -ny, nx


def _mover_lines(
    movers: list[list[float]],
    mover_r: list[float],
    at: list[float],
    v_own: Vec,
    radius: float,
    max_speed: float,
    horizon: float,
    dt: float,
    margin: float,
) -> list[Line]:
    """The half-planes of the moving obstacles (x, y, vx, vy rows) that can reach the robot at `at` within the
    horizon; the robot takes all of the avoidance (a mover does not react)."""
    lines = []
    for (mx, my, mvx, mvy), mr in zip(movers, mover_r, strict=False):  # movers sensed: at most len(mover_r)
        qx, qy = mx - at[0], my - at[1]
        if math.sqrt(qx * qx + qy * qy) < max_speed * horizon * 2 + mr:  # it can be reached in time
            away = v_own[0] - mvx, v_own[1] - mvy
            lines.append(_line((qx, qy), away, radius + mr + margin, horizon, dt, 1.0, v_own))
    return lines


def avoid_movers(
    pref: np.ndarray,
    obs: Observation,
    radius: float,
    max_speed: float,
    mover_radius: np.ndarray,
    horizon: float = ORCA_HORIZON,
    dt: float = ORCA_RECOVERY,
    margin: float = ORCA_MARGIN,
) -> np.ndarray:
    """`pref` (n, 2) with only the moving obstacles avoided, ORCA's way: a robot that no mover can reach within the
    horizon keeps its velocity to the bit; one that a mover can reach takes the velocity nearest its own that avoids
    the mover and approaches the nearest static obstacle point no faster than ORCA allows (so that stepping aside
    does not push it into a wall). A safety layer for controllers that do not see a mover's velocity (the learned
    methods' networks, L&F's approach cap on a differential drive)."""
    mover_r = np.asarray(mover_radius, dtype=float).tolist()
    movers = obs.movers[: len(mover_r)].tolist()
    out = pref.copy()
    if not movers:
        return out
    position, velocity = obs.position.tolist(), obs.velocity.tolist()
    for i in range(len(pref)):
        v_own = velocity[i][0], velocity[i][1]
        lines = _mover_lines(movers, mover_r, position[i], v_own, radius, max_speed, horizon, dt, margin)
        if not lines:
            continue
        # the robots it senses, the avoidance all its own (they may not be stepping aside): a robot that dodges a
        # mover does not dodge into its neighbour
        for j in np.flatnonzero(obs.neighbours[i]).tolist():
            qx, qy = obs.rel_position[i, j].tolist()
            ux, uy = obs.rel_velocity[i, j].tolist()
            lines.append(_line((qx, qy), (-ux, -uy), 2 * radius + margin, horizon, dt, 1.0, v_own))
        wall = _wall_line(obs.obstacle[i].tolist(), float(obs.obstacle_distance[i]), margin, max_speed, horizon)
        n_fixed = 0
        if wall is not None:
            lines.insert(0, wall)
            n_fixed = 1
        count, result = _lp2(lines, max_speed, (float(pref[i, 0]), float(pref[i, 1])), False)
        if count < len(lines):
            result = _lp3(lines, n_fixed, count, max_speed, result)
        out[i] = result
    return out
