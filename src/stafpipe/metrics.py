"""Episode metrics: pure functions of a recorded trajectory, the same for a live run and a run read back from MCAP.

STAF Section 4: SR (robots at their goal without any collision), TT (time until the whole
team is at its goal), CFI (Appendix D; thresholds sigma = 0.5, 0.1, 0.01, w = 0.5). Cezayirli & Kerestecioglu Fig. 4:
number of communication links over time; we add the algebraic connectivity lambda2 of the same graph. Where STAF's
printed CFI is ill-posed we use its evident intent (docs/metrics.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

from stafpipe.geometry import PathFrame
from stafpipe.integrity import formation_integrities

CFI_SIGMAS = (0.5, 0.1, 0.01)  # STAF Table 1 columns
CFI_WEIGHT = 0.5  # STAF Appendix D: w = 0.5


@dataclass
class Trajectory:
    """What an episode recorded, step by step (T + 1 samples including the start)."""

    time: np.ndarray
    """(T+1,) seconds."""
    positions: np.ndarray
    """(T+1, n, 2)."""
    velocities: np.ndarray
    """(T+1, n, 2)."""
    subteams: np.ndarray
    """(T+1, n) int subteam id of each robot (all 0 when the team is whole)."""
    team_goal: np.ndarray
    """(n, 2) the team's goal slots (the scenario's goal formation)."""
    obstacle_distance: np.ndarray
    """(T+1, n) distance from each robot's surface to the nearest obstacle."""
    collisions: list[tuple[int, int, int]] = field(default_factory=list)
    """(step, robot a, robot b or -1 for an obstacle) for every contact that began."""

    @cached_property
    def goal_distance(self) -> np.ndarray:
        """(T+1, n) each robot's distance to its goal slot, robots matched to slots at every sample (computed once:
        TT, TT of arrivals and the subteams' metrics all read it)."""
        return np.stack([matched_goal_distance(p, self.team_goal) for p in self.positions])

    def route_passed(self, route) -> int:
        """`route_done` of these positions, worked out once per route (SR, TT, TT of arrivals and the subteams'
        metrics all ask)."""
        key = tuple(tuple(map(float, p)) for p in route)
        memo = self.__dict__.setdefault("_route_passed", {})
        if key not in memo:
            memo[key] = route_done(self.positions, key)
        return memo[key]


@dataclass
class MetricContext:
    """What the metrics need besides the trajectory: the robot, formation and geometry of the scenario."""

    robot_radius: float
    formation: str
    spacing: float
    angle_deg: float
    heading_deg: float
    passage_width: float
    """Narrowest passage on the way (STAF's eta before the safety margin), from geometry.Geometry."""
    travel_time_lower_bound: float
    goal_tolerance: float = 0.3
    sensing_radius: float = 2.0
    cfi_margin: float = 0.1
    occlusion: bool = False
    """Whether robots hide robots behind them (`sensing.occlusion`): a link is then a pair that sense each other."""
    """Safety margin taken off each side of the passage: eta = passage_width - 2 margin (STAF Sec. 4 'with safety
    margin')."""
    path: tuple = ()
    """The team centre's shortest path ((x, y), ...) that `passages` measure along (empty: no passage known)."""
    passages: tuple = ()
    """((from, to), ...) arc lengths along `path` where the whole team in its formation does not fit across the free
    width (`episode.narrow_stretches`): where CFI's gap term has a gap to judge (`cfi_passage_*`)."""
    route: tuple = ()
    """The scenario's reference waypoints ((x, y), ...) the team must pass, in order, before its goal counts (empty:
    none; `route_done`)."""


ROUTE_REACH = 1.0
"""m: a reference waypoint counts as passed once the team's centroid or one of its robots has come this close
(`route_done`; chosen, not tuned: a robot's spacing in the paper's formations). docs/metrics.md."""


def waypoint_gap(positions: np.ndarray, waypoint: np.ndarray) -> np.ndarray:
    """(..,) distance from a waypoint to the team at `positions` (.., n, 2): to its centroid or its nearest robot,
    whichever is closer (how `route_done` passes a waypoint)."""
    centroid = np.linalg.norm(positions.mean(axis=-2) - waypoint, axis=-1)
    return np.minimum(centroid, np.linalg.norm(positions - waypoint, axis=-1).min(-1))


def route_done(positions: np.ndarray, route, reach: float = ROUTE_REACH) -> int:
    """Index of the first sample (of `positions`, (T, n, 2)) by which the team has passed every waypoint of `route`,
    in order: 0 without a route, T if it never does. A route that comes back near its start (Zhu et al. 2019,
    Scenario 1) would otherwise count a team that never left as arrived."""
    k = 0
    for waypoint in route:
        hits = np.flatnonzero(waypoint_gap(positions[k:], np.asarray(waypoint, float)) <= reach)
        if not len(hits):
            return len(positions)
        k += int(hits[0])
    return k


class RouteProgress:
    """Each world's place on its route, step by step: `route_done` for a team that is still moving (the trainer's and
    the multi-agent environment's arrival bonus waits for the route as SR does)."""

    def __init__(self, routes: list, reach: float = ROUTE_REACH) -> None:
        self.routes = [np.asarray(r, dtype=float).reshape(-1, 2) for r in routes]
        self.lengths = np.array([len(r) for r in self.routes])
        self.next = np.zeros(len(self.routes), dtype=int)
        self.reach = reach

    def update(self, pos: np.ndarray) -> np.ndarray:
        """(B,) bool: world w's team (positions `pos`, (B, n, 2)) has passed every waypoint of its route, in order."""
        for w in np.flatnonzero(self.next < self.lengths).tolist():
            while self.next[w] < self.lengths[w]:
                if waypoint_gap(pos[w], self.routes[w][self.next[w]]) > self.reach:
                    break
                self.next[w] += 1
        return self.next >= self.lengths


def matched_goal_distance(pos: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Distance of each robot to the goal slot it is matched to (Hungarian, robots interchangeable)."""
    cost = cdist(pos, goal)
    rows, cols = linear_sum_assignment(cost)
    out = np.empty(len(pos))
    out[rows] = cost[rows, cols]
    return out


def success_rate(traj: Trajectory, ctx: MetricContext) -> float:
    """SR: fraction of robots within tolerance of a goal slot at the end, that never collided."""
    at_goal = matched_goal_distance(traj.positions[-1], traj.team_goal) <= ctx.goal_tolerance
    at_goal &= traj.route_passed(ctx.route) < len(traj.positions)  # the route passed, if it has one
    hit = np.zeros(traj.positions.shape[1], dtype=bool)
    for _, a, b in traj.collisions:
        hit[a] = True
        if b >= 0:
            hit[b] = True
    return float(np.mean(at_goal & ~hit))


def travel_time(traj: Trajectory, ctx: MetricContext) -> float:
    """TT: first time at which every robot is within tolerance of a goal slot, the route passed (`route_done`); NaN if
    that never happens."""
    done = np.flatnonzero((traj.goal_distance <= ctx.goal_tolerance).all(axis=1))
    done = done[done >= traj.route_passed(ctx.route)]
    return float(traj.time[done[0]]) if len(done) else math.nan


def travel_time_of_arrivals(traj: Trajectory, ctx: MetricContext) -> float:
    """TT over the robots that arrive: the first time at which every robot that ends the episode at a goal slot is
    within tolerance of one (equals TT when the whole team arrives; NaN when nobody does). STAF's Table 1 prints a TT
    for L&F although its SR is 40-70 %: this is our reading of it (docs/metrics.md)."""
    distance = traj.goal_distance
    arrived = distance[-1] <= ctx.goal_tolerance
    passed = traj.route_passed(ctx.route)
    if not arrived.any() or passed >= len(distance):
        return math.nan
    done = np.flatnonzero((distance[:, arrived] <= ctx.goal_tolerance).all(axis=1))
    return float(traj.time[done[done >= passed][0]])


def _group_terms(
    traj: Trajectory, ctx: MetricContext, ks: np.ndarray, idx: np.ndarray, memo: dict | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(diameter 2r, epsilon) of the robots `idx` at each sample of `ks`, vectorised over the samples; `memo` shares
    them between the team's CFI and the subteams' (Table 2), which judge the same groups at the same samples."""
    memo = {} if memo is None else memo
    group = idx.tobytes()
    todo = np.array([k for k in ks if (k, group) not in memo], dtype=int)
    if len(todo):
        p = traj.positions[todo][:, idx]  # (K, k, 2)
        diam = 2.0 * (np.linalg.norm(p - p.mean(axis=1, keepdims=True), axis=-1).max(axis=1) + ctx.robot_radius)
        v = traj.velocities[todo][:, idx].mean(axis=1)  # the group faces where it moves, if it moves at all
        moving = np.linalg.norm(v, axis=-1) > 0.05
        heading = np.where(moving, np.arctan2(v[:, 1], v[:, 0]), math.radians(ctx.heading_deg))
        eps = formation_integrities(p, ctx.formation, ctx.spacing, heading, ctx.angle_deg)
        for k, d, e in zip(todo, diam, eps, strict=True):
            memo[(k, group)] = (float(d), float(e))
    terms = [memo[(k, group)] for k in ks]
    return np.array([d for d, _ in terms]), np.array([e for _, e in terms])


def _entries(traj: Trajectory) -> list[tuple[int, np.ndarray]]:
    """(sample, robots of one subteam) for every subteam at every sample: samples in order, subteams by id."""
    return [(k, np.flatnonzero(sub == team)) for k, sub in enumerate(traj.subteams) for team in np.unique(sub)]


def in_passage(positions: np.ndarray, ctx: MetricContext) -> np.ndarray:
    """(T+1, n) whether each robot's projection on the team's path lies in one of `ctx.passages`."""
    if not ctx.passages or len(ctx.path) < 2:
        return np.zeros(positions.shape[:2], dtype=bool)
    s = PathFrame(np.asarray(ctx.path, float)).progress(positions.reshape(-1, 2)).reshape(positions.shape[:2])
    return np.any([(s >= lo) & (s <= hi) for lo, hi in ctx.passages], axis=0)


def cfi_terms(
    traj: Trajectory, ctx: MetricContext, memo: dict | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per (sample, subteam): the team's diameter 2 r (r = max distance of a robot's edge from the subteam's centroid),
    its integrity epsilon, and whether any of its robots is in a passage (`cfi_passage_*`). Returns flat arrays,
    samples in order, subteams by id within one."""
    memo = {} if memo is None else memo
    entries = _entries(traj)
    groups: dict[bytes, tuple[np.ndarray, list[int]]] = {}
    for k, idx in entries:
        groups.setdefault(idx.tobytes(), (idx, []))[1].append(k)
    for idx, ks in groups.values():  # each group of robots over all the samples it stands as a subteam
        _group_terms(traj, ctx, np.array(ks), idx, memo)
    terms = [memo[(k, idx.tobytes())] for k, idx in entries]
    inside = in_passage(traj.positions, ctx)
    in_a_passage = np.array([bool(inside[k, idx].any()) for k, idx in entries], dtype=bool)
    return np.array([d for d, _ in terms]), np.array([e for _, e in terms]), in_a_passage


def subteam_metrics(traj: Trajectory, ctx: MetricContext, memo: dict | None = None) -> dict[str, float]:
    """STAF Table 2 (STAF-sub1, STAF-sub2, ...): SR, TT and CFI of each subteam of the team's first split, subteams
    numbered by their id (STAF's plan numbers them in the order they pass). SR and TT as for the team, over the
    subteam's robots (goal slots matched over the whole team); CFI over the samples while the team is split. Empty
    when the team never splits."""
    split = [k for k in range(len(traj.time)) if len(np.unique(traj.subteams[k])) > 1]
    if not split:
        return {}
    labels = traj.subteams[split[0]]
    hit = np.zeros(traj.positions.shape[1], dtype=bool)
    for _, a, b in traj.collisions:
        hit[[a, b] if b >= 0 else [a]] = True
    matched = traj.goal_distance
    passed = traj.route_passed(ctx.route)
    eta = ctx.passage_width - 2.0 * ctx.cfi_margin
    out: dict[str, float] = {}
    for j, team in enumerate(np.unique(labels)):
        idx = np.flatnonzero(labels == team)
        done = np.flatnonzero((matched[:, idx] <= ctx.goal_tolerance).all(axis=1))
        done = done[done >= passed]
        home = (matched[-1, idx] <= ctx.goal_tolerance) & (passed < len(matched))
        out[f"sub{j + 1}_sr"] = float(np.mean(home & ~hit[idx]))
        out[f"sub{j + 1}_tt"] = float(traj.time[done[0]]) if len(done) else math.nan
        diam, eps = _group_terms(traj, ctx, np.array(split), idx, memo)
        for sigma in CFI_SIGMAS:
            out[f"sub{j + 1}_cfi_{sigma:g}"] = cfi(diam, eps, eta, sigma)
    return out


def cfi(diameter: np.ndarray, epsilon: np.ndarray, eta: float, sigma: float, w: float = CFI_WEIGHT) -> float:
    """CFI at threshold sigma, averaged over samples and subteams.

    Printed (STAF Sec. 4 / App. D): w (1 - sigma^-1 min(|r - (eta + sigma)|, |r - (eta - sigma)|)) + (1 - w) epsilon.
    Used: gap = 1 inside the band |2r - eta| <= sigma, falling linearly to 0 one sigma outside it, i.e.
    clip(1 - max(0, |2r - eta| - sigma) / sigma, 0, 1); see docs/metrics.md for why.
    """
    gap = np.clip(1.0 - np.maximum(0.0, np.abs(diameter - eta) - sigma) / sigma, 0.0, 1.0)
    return float(np.mean(w * gap + (1.0 - w) * epsilon))


def cfi_printed(diameter: np.ndarray, epsilon: np.ndarray, eta: float, sigma: float, w: float = CFI_WEIGHT) -> float:
    """CFI with the gap term exactly as printed (STAF Sec. 4 / App. D), r the subteam's maximum radius (diameter / 2)
    against eta: w (1 - sigma^-1 min(|r - (eta + sigma)|, |r - (eta - sigma)|)) + (1 - w) epsilon, the gap term
    clipped to [0, 1] (unclipped it goes far below 0). Reported beside `cfi` so that both readings can be compared
    (docs/metrics.md)."""
    r = diameter / 2.0
    gap = 1.0 - np.minimum(np.abs(r - (eta + sigma)), np.abs(r - (eta - sigma))) / sigma
    return float(np.mean(w * np.clip(gap, 0.0, 1.0) + (1.0 - w) * epsilon))


def connectivity(positions: np.ndarray, radius: float, occlusion_radius: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: number of undirected links and algebraic connectivity lambda2 of that graph. A link: two robots
    within `radius`; with `occlusion_radius` (the robots' radius, when sensing has occlusion) also each seeing the
    other, no robot in between hiding any part of it (Cezayirli Section II: "partially occluded = occluded"), so the
    graph is that of sensed neighbours, as Cezayirli Fig. 4 counts them."""
    from stafpipe.sensing import occluded

    rel = positions[:, None] - positions[:, :, None]  # (T, n, n, 2): [t, i, j] = p_j - p_i
    d = np.linalg.norm(rel, axis=-1)
    n = positions.shape[1]
    adj = (d <= radius) & ~np.eye(n, dtype=bool)
    if occlusion_radius > 0:
        hidden = occluded(rel, d, occlusion_radius)
        adj &= ~hidden & ~np.swapaxes(hidden, -1, -2)
    links = adj.sum(axis=(1, 2)) // 2
    if n < 2:
        return links, np.zeros(len(positions))
    degree = adj.sum(axis=2)
    lap = degree[:, :, None] * np.eye(n) - adj.astype(float)  # every sample's graph Laplacian at once
    return links, np.maximum(0.0, np.sort(np.linalg.eigvalsh(lap), axis=-1)[:, 1])


def episode_metrics(traj: Trajectory, ctx: MetricContext) -> dict[str, float]:
    """Every metric of one episode, as a flat dict (one row of the results table)."""
    eta = ctx.passage_width - 2.0 * ctx.cfi_margin
    memo: dict = {}
    diam, eps, inside = cfi_terms(traj, ctx, memo)
    links, lam2 = connectivity(traj.positions, ctx.sensing_radius, ctx.robot_radius if ctx.occlusion else 0.0)
    pos = traj.positions
    n = pos.shape[1]
    gaps = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1) + np.eye(n)[None] * 1e9
    tt = travel_time(traj, ctx)
    out = {
        "sr": success_rate(traj, ctx),
        "tt": tt,
        "tt_arrived": travel_time_of_arrivals(traj, ctx),
        "tt_lower_bound": ctx.travel_time_lower_bound,
        "tt_ratio": tt / ctx.travel_time_lower_bound if ctx.travel_time_lower_bound > 0 else math.nan,
        "eta": eta,
        "formation_integrity": float(eps.mean()),
        "collisions": float(len(traj.collisions)),
        "robot_collisions": float(sum(1 for c in traj.collisions if c[2] >= 0)),
        "obstacle_collisions": float(sum(1 for c in traj.collisions if c[2] < 0)),
        "min_robot_gap": float(gaps.min() - 2 * ctx.robot_radius),
        "min_obstacle_distance": float(traj.obstacle_distance.min()),
        "path_length": float(np.linalg.norm(np.diff(pos, axis=0), axis=2).sum(axis=0).mean()),
        "links_mean": float(links.mean()),
        "links_min": float(links.min()),
        "lambda2_mean": float(lam2.mean()),
        "lambda2_min": float(lam2.min()),
        "subteams_max": float(max(len(np.unique(s)) for s in traj.subteams)),
        "duration": float(traj.time[-1]),
    }
    for sigma in CFI_SIGMAS:
        out[f"cfi_{sigma:g}"] = cfi(diam, eps, eta, sigma)
    for sigma in CFI_SIGMAS:
        out[f"cfi_printed_{sigma:g}"] = cfi_printed(diam, eps, eta, sigma)
    for sigma in CFI_SIGMAS:  # the same CFI over the samples a subteam spends in the passage (docs/metrics.md)
        out[f"cfi_passage_{sigma:g}"] = cfi(diam[inside], eps[inside], eta, sigma) if inside.any() else math.nan
    out.update(subteam_metrics(traj, ctx, memo))
    return out
