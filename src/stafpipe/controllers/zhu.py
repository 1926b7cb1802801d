"""`method=zhu`: distributed formation splitting and merging (Zhu, Juhl, Ferranti and Alonso-Mora, ICRA 2019), 2D.

Every `control_period` (the 5 Hz of Section V-A) each robot grows its obstacle-free convex region P_i within its
visibility r_B (`convex_region.grow_region`; moving obstacles swept over the horizon tau, Eq. (1)), and each (sub)team
fits its template formation in its common region P^k = ∩ P_i nearest the global reference p_r (Section III, after
[20]) and assigns robots to slots (Hungarian method; [20] uses a distributed assignment with the same optimum). Every
`decision_period` (ff = 1 s) the teams run the consensus steps: communication-loss detection, the split check on the
intersection graph (Algorithm 1) and merging (Algorithm 2). Stuck faults are checked every step (Section IV-D). ORCA
(controllers/orca.py) makes the step towards each slot collision-free (the paper's local planner is [22]'s MPC).

The robots' computations are identical given the flooded regions (Remark 1), so each team's decision is computed once
here; the flooding itself is modelled by the connected components of the team's communication graph
(`zhu_decisions.comm_components`) over the links the world delivers (`Observation.heard`). Faults are injected by
the world for every method (`world.faults`, stafpipe.faults: a stuck robot's actuators ignore their commands, a
silent robot sends nothing); detection never reads that list.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from stafpipe.controllers.base import Controller, TeamInfo, limit_approach
from stafpipe.controllers.orca import orca_velocities
from stafpipe.controllers.plan_geometry import separated
from stafpipe.controllers.zhu_config import ZhuConfig
from stafpipe.controllers.zhu_decisions import (
    StuckDetector,
    TeamStall,
    comm_components,
    intersection_graph,
    merge_candidate,
    merge_requests,
    mutual_merges,
    needs_split,
    spectral_partition,
    split_team,
)
from stafpipe.convex_region import (
    Region,
    fit_centres,
    footprint_area,
    grow_halfplanes,
    hull_vertices,
    intersect_all,
    regions_from_halfplanes,
)
from stafpipe.formations import assign_slots, formation_slots, rotation
from stafpipe.geometry import Geometry, capsule_arrays, path_parts, point_ahead
from stafpipe.sensing import Observation

SIGHT_GAP = 0.05
"""A team sees p_r when the straight way from its centre keeps this far (m) from every obstacle (`team_reference`)."""
TIMED_PARTS = ("convex_regions", "split_check", "graph_partition", "merge_decision", "formation_control")
"""Table I's rows."""


def grid_slots(m: int, across: int, spacing: float) -> np.ndarray:
    """m robots in rows of `across` (across the direction of travel), rows one behind the other; centroid at 0."""
    rows = [divmod(k, across) for k in range(m)]
    pts = np.array([(-r * spacing, ((min(across, m - r * across) - 1) / 2 - c) * spacing) for r, c in rows], float)
    return pts - pts.mean(axis=0)


class ZhuController(Controller):
    """Split and merge formations by convex regions, the intersection graph and consensus."""

    def __init__(self, cfg: ZhuConfig) -> None:
        super().__init__()
        cfg.check()
        self.cfg = cfg

    def reset(self, team: TeamInfo) -> None:
        super().reset(team)
        cfg, spec = self.cfg, team.scenario.spec
        self.radius, self.speed = spec.robot.radius, spec.robot.max_speed
        self.formation, self.spacing, self.angle = spec.team.formation, spec.team.spacing, spec.team.angle_deg
        self.static = capsule_arrays(team.scenario)
        self.mover_radius = np.array([m.radius for m in spec.moving_obstacles])
        self.path, self.goal = team.path, team.goal
        seg = np.linalg.norm(np.diff(self.path, axis=0), axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(seg)])
        self.path_parts = path_parts(self.path)  # for the teams' own references (`team_reference`)
        self.geometry = Geometry.of(team.scenario)
        self._blind_since: dict[tuple[int, ...], float] = {}
        self._sight: dict[tuple[int, ...], bool] = {}  # `_blind` of each team in this control step
        self._now = 0.0
        self.s_ref = 0.0
        self._ref: tuple[float, np.ndarray, float] | None = None
        self.teams: dict[int, list[int]] = {1: list(range(self.n))}
        self.next_id = 2
        self._shapes: dict[int, list[np.ndarray]] = {}
        self._hulls: dict[int, np.ndarray] = {}
        self._v_min: dict[int, float] = {}
        self._choice: dict[int, tuple[int, int, float] | None] = {}
        self._held: dict[int, np.ndarray] = {}
        self.next_control = self.next_decision = 0.0
        self.regions: list[Region] = []
        self.common: dict[int, Region] = {}
        self.timings: dict[str, list[float]] = {p: [] for p in TIMED_PARTS}
        self.stuck = StuckDetector(self.n, cfg.n_dead, cfg.dp_min, cfg.stuck_near)
        self.stall = TeamStall(cfg.stall_time, cfg.dp_min)
        for m in range(1, self.n + 1):  # templates, hulls and V_min of every team size, before the clock runs
            self.v_min(m)
            for shape in self.shapes(m):
                self._hull(shape)
        self._sync_subteams()

    def episode_stats(self) -> dict[str, float]:
        """Table I per episode: min / mean / max / std of each part's time (ms per control cycle, whole team)."""
        out = {}
        for part, samples in self.timings.items():
            x = np.array(samples) if samples else np.full(1, np.nan)
            for stat, f in (("min", np.min), ("mean", np.mean), ("max", np.max), ("std", np.std)):
                out[f"time_{part}_{stat}"] = float(f(x))
            out[f"time_{part}_count"] = float(len(samples))
        return out

    # ---- the reference, templates and regions ------------------------------------------------------------------

    def reference(self) -> tuple[np.ndarray, float]:
        """p_r (Section II: "a global reference center position p_r for the team is given") and the path heading."""
        if self._ref is not None and self._ref[0] == self.s_ref:
            return self._ref[1], self._ref[2]
        s = min(self.s_ref, self.cum[-1])
        j = int(np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.path) - 2))
        d = self.path[j + 1] - self.path[j]
        length = max(float(np.linalg.norm(d)), 1e-9)
        self._ref = (self.s_ref, self.path[j] + (s - self.cum[j]) / length * d, math.atan2(d[1], d[0]))
        return self._ref[1], self._ref[2]

    def team_reference(self, members: list[int], p: np.ndarray) -> tuple[np.ndarray, float]:
        """Where team `members` aims: p_r and the path's heading there, or for a team more than max_lag from p_r whose
        straight way to it crosses an obstacle, and has for `team_wait` seconds (`team_reference`, `_watch_sight`),
        the path's point `team_lookahead` ahead of the team centre's projection on it, if that is short of p_r, and
        the heading there."""
        ref, heading = self.reference()
        if not self.cfg.team_reference or not self._blind(members, p):
            return ref, heading
        centre = p[members].mean(axis=0)
        if self.cfg.team_wait > 0 and self._now - self._blind_since.get(tuple(members), self._now) < self.cfg.team_wait:
            return ref, heading
        ahead = self.cfg.team_lookahead
        point, direction, left = point_ahead(self.path, centre[None], ahead, self.path_parts)
        if self.cum[-1] - float(left[0]) + ahead >= min(self.s_ref, self.cum[-1]):
            return ref, heading
        return point[0], math.atan2(direction[0, 1], direction[0, 0])

    def _watch_sight(self, p: np.ndarray, t: float) -> None:
        """With `team_wait`: since when each team (but the whole team) has stood more than max_lag from p_r with its
        straight way to p_r crossing an obstacle; a team that sees p_r, or is near it, starts afresh."""
        self._now, self._sight = t, {}
        if not self.cfg.team_reference or self.cfg.team_wait <= 0:
            return
        blind = [tuple(m) for m in self.teams.values() if self._blind(m, p)]
        self._blind_since = {key: self._blind_since.get(key, t) for key in blind}

    def _blind(self, members: list[int], p: np.ndarray) -> bool:
        """Whether team `members` (not the whole team) stands more than max_lag from p_r and its centre's straight way
        to p_r crosses an obstacle; worked out once per team and control step (`_watch_sight` starts each step afresh:
        the regions and the formation control both ask)."""
        key = tuple(members)
        if key not in self._sight:
            ref, _ = self.reference()
            centre = p[members].mean(axis=0)
            far = len(members) < self.n and float(np.linalg.norm(centre - ref)) > self.cfg.max_lag
            self._sight[key] = far and not self.geometry.visible(centre, ref, SIGHT_GAP)
        return self._sight[key]

    def _at_goal(self) -> bool:
        """p_r has reached the end of the team's path."""
        return self.s_ref >= self.cum[-1] - 1e-9

    def shapes(self, m: int) -> list[np.ndarray]:
        """The template formations a team of m robots may take, preferred first (Section II: "a predefined set of
        default formations ... known by all robots"): the scenario's formation, then grids two wide and one wide."""
        if m not in self._shapes:
            if m == 1:
                self._shapes[m] = [np.zeros((1, 2))]
            else:
                out = [formation_slots(self.formation, m, self.spacing, self.angle)]
                out += [grid_slots(m, w, self.spacing) for w in (2, 1) if w < m]
                self._shapes[m] = out
        return self._shapes[m]

    def _hull(self, shape: np.ndarray) -> np.ndarray:
        key = id(shape)  # shapes are cached per team size, so their ids are stable
        if key not in self._hulls:
            self._hulls[key] = hull_vertices(shape)
        return self._hulls[key]

    def v_min(self, m: int) -> float:
        """V_min of a team of m robots (Section IV-B: "the smallest size that allows for a template formation")."""
        if self.cfg.v_min is not None:
            return self.cfg.v_min
        if m not in self._v_min:
            self._v_min[m] = footprint_area(self.shapes(m)[0], self.radius) if m > 1 else 0.0
        return self._v_min[m]

    def _obstacles(self, obs: Observation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Static capsules plus each moving obstacle swept over [0, tau] at constant velocity (Eq. (1), Section II)."""
        a, b, r = self.static
        if len(self.mover_radius) == 0:
            return a, b, r
        m = obs.movers[: len(self.mover_radius)]
        return (
            np.concatenate([a, m[:, :2]]),
            np.concatenate([b, m[:, :2] + self.cfg.horizon * m[:, 2:]]),
            np.concatenate([r, self.mover_radius]),
        )

    def grow_regions(self, obs: Observation) -> list[Region]:
        """Every robot's P_i (Algorithm 1, step 2)."""
        a, b, r = self._obstacles(obs)
        ahead = np.empty_like(obs.position)
        for members in self.teams.values():
            ahead[members] = self.team_reference(members, obs.position)[0] - obs.position[members]
        ahead /= np.maximum(np.linalg.norm(ahead, axis=1, keepdims=True), 1e-9)
        # once p_r has reached the goal there is no "ahead" left: the teams regroup round it in whole discs
        behind = math.inf if self._at_goal() else self.cfg.behind
        return regions_from_halfplanes(
            grow_halfplanes(
                obs.position, a, b, r, self.cfg.visibility, self.radius, ahead, behind, self.cfg.visibility_sides
            )
        )

    # ---- one step ------------------------------------------------------------------------------------------------

    def act(self, obs: Observation) -> np.ndarray:
        cfg, t, p = self.cfg, float(obs.time), obs.position
        comm = obs.heard & obs.heard.T  # r_C = sensing.radius; two-way links only (a silent robot has none)
        self._detect_stuck(p)
        if t + 1e-9 >= self.next_control:
            self.next_control += cfg.control_period
            self._advance_reference(p)
            self._watch_sight(p, t)
            with self._timed("convex_regions"):
                self.regions = self.grow_regions(obs)
            decided = t + 1e-9 >= self.next_decision
            if decided:
                self.next_decision += cfg.decision_period
                self._decide(p, comm, t)
            with self._timed("formation_control"):
                self._formation_control(p)
            if decided:  # the teams' common regions, for `stafpipe plot regions` (Zhu Fig. 4), to the centimetre
                self.emit(
                    "regions",
                    list(range(self.n)),
                    json.dumps({str(k): np.round(r.vertices, 2).tolist() for k, r in self.common.items()}),
                )
        v = cfg.gain * (self._targets - p)
        speed = np.linalg.norm(v, axis=1, keepdims=True)
        v *= np.minimum(1.0, self.speed / np.maximum(speed, 1e-9))
        if cfg.local_planner == "orca":
            return orca_velocities(
                v, obs, self.radius, self.speed, cfg.orca_horizon, cfg.orca_recovery, cfg.orca_margin, self.mover_radius
            )
        return limit_approach(v, obs, self.radius, cfg.avoid_distance, cfg.avoid_gain, cfg.stop_gap)

    @contextmanager
    def _timed(self, part: str) -> Iterator[None]:
        t0 = time.perf_counter()
        yield
        self.timings[part].append(1e3 * (time.perf_counter() - t0))

    def _advance_reference(self, p: np.ndarray) -> None:
        ref, _ = self.reference()
        lag = min(float(np.linalg.norm(p[m].mean(axis=0) - ref)) for m in self.teams.values())
        if lag <= self.cfg.max_lag:
            self.s_ref = min(self.s_ref + self.cfg.reference_speed * self.cfg.control_period, float(self.cum[-1]))

    def _detect_stuck(self, p: np.ndarray) -> None:
        flags = self.stuck.update(p, self._targets)
        for i in np.flatnonzero(flags):
            members = self.teams[int(self._subteams[i])]
            if len(members) > 1:  # Section IV-D: the stuck robot leaves; the reduced formation goes on
                members.remove(int(i))
                self._new_team([int(i)])
                self.emit("stuck", [int(i)], f"progress < {self.cfg.dp_min:g} m over {self.cfg.n_dead} steps")
                self._held[int(i)] = p[i].copy()
                self._sync_subteams()
            self.stuck.reset(int(i))

    # ---- consensus decisions (every ff seconds) -------------------------------------------------------------------

    def _new_team(self, members: list[int]) -> int:
        self.teams[self.next_id] = sorted(members)
        self.next_id += 1
        return self.next_id - 1

    def _sync_subteams(self) -> None:
        for k, members in self.teams.items():
            self._subteams[members] = k

    def _decide(self, p: np.ndarray, comm: np.ndarray, t: float) -> None:
        # communication loss (Section IV-D): robots a team's flooding did not reach within d rounds are discarded
        for k in list(self.teams):
            parts = comm_components(comm, self.teams[k])
            if len(parts) > 1:
                self.teams[k] = parts[0]
                for part in parts[1:]:
                    self._new_team(part)
                    self.emit("comm_loss", part, f"not heard by team {k} within its consensus rounds")
        ref, _ = self.reference()
        at = {tuple(m): (c := p[m].mean(axis=0), float(np.linalg.norm(c - ref))) for m in self.teams.values()}
        stalled = self.stall.update(t, at, self.cfg.max_lag) if self.cfg.stall_time > 0 else []
        # split check and partition (Algorithm 1); a stalled team splits in two by the same partition (TeamStall)
        home = self._at_goal()  # the whole team then takes its goal slots (_formation_control) and never splits
        for k in list(self.teams):
            members = self.teams[k]
            if len(members) < 2 or (home and len(members) == self.n):
                continue
            with self._timed("split_check"):
                a = intersection_graph([self.regions[i] for i in members])
                split = needs_split(a, self.v_min(len(members)))
            if split or tuple(members) in stalled:
                with self._timed("graph_partition"):
                    v_of = {m: self.v_min(m) for m in range(1, len(members) + 1)}
                    labels = split_team(a, v_of, self.cfg.max_subteams) if split else spectral_partition(a, 2)
                groups = [[members[i] for i in np.flatnonzero(labels == g)] for g in range(labels.max() + 1)]
                self.teams[k] = groups[0]
                for g in groups[1:]:
                    self._new_team(g)
                why = "" if split else f"stalled {self.cfg.stall_time:g} s over {self.cfg.max_lag:g} m from p_r; "
                if not split:  # its parts rejoin only once they move, as a stuck robot does (else at once: same place)
                    self._held.update({i: p[i].copy() for i in members})
                self.emit(
                    "split",
                    sorted(members),
                    f"{why}A_a min {a[~np.eye(len(a), dtype=bool)].min():.2f} {'<' if split else '>='} "
                    f"V_min {self.v_min(len(members)):.2f}; parts {groups}",
                )
        self._sync_subteams()
        with self._timed("merge_decision"):
            self._merge(p, comm)
        self._sync_subteams()

    def _merge(self, p: np.ndarray, comm: np.ndarray) -> None:
        """Section IV-C and Algorithm 2."""
        if len(self.teams) < 2:
            return
        ids = list(self.teams)
        common = dict(zip(ids, intersect_all([[self.regions[i] for i in self.teams[k]] for k in ids]), strict=True))
        centre = {k: p[m].mean(axis=0) for k, m in self.teams.items()}
        pairs = [(k, l) for k in ids for l in ids if k < l]
        both_of = dict(zip(pairs, intersect_all([[common[k], common[l]] for k, l in pairs]), strict=True))
        candidates = {}
        # a robot dropped as stuck asks to merge only once it moves again (Section IV-D: "after the detection of the
        # stuck fault (temporary fault), it tries to ... merge"): here, once it is 0.5 spacing from where it stopped
        for i, at in list(self._held.items()):
            if np.linalg.norm(p[i] - at) > 0.5 * self.spacing:
                del self._held[i]
        held = {int(self._subteams[i]) for i in self._held}
        for k, l in pairs:
            if k in held or l in held:
                continue
            mk, ml = self.teams[k], self.teams[l]
            both = both_of[(k, l)]
            in_range = bool(comm[np.ix_(mk, ml)].any())
            if merge_candidate(centre[k], centre[l], both, self.cfg.p_max, self.v_min(len(mk) + len(ml)), in_range):
                candidates[(k, l)] = candidates[(l, k)] = both.area
        for k, l in mutual_merges(merge_requests(self.teams, comm, candidates)):
            merged = sorted(self.teams.pop(k) + self.teams.pop(l))
            self.teams[min(k, l)] = merged
            for i in merged:
                self.stuck.reset(i)
            self.emit("merge", merged, f"teams {k} and {l}")

    # ---- local formation control (Section III) ---------------------------------------------------------------------
    def _formation_control(self, p: np.ndarray) -> None:
        at_end = self._at_goal()
        ids = list(self.teams)
        self.common = dict(
            zip(ids, intersect_all([[self.regions[i] for i in self.teams[k]] for k in ids]), strict=True)
        )
        room = self._clear_of_other_teams(p) if len(ids) > 1 else {}
        # at the goal a team takes the goal slots one assignment of all robots gives its members (the whole team: all
        # of them; ours, home_slots: every team not left behind out of sight, so that no two teams cross for slots)
        home = self.goal[assign_slots(p, self.goal)] if at_end else self.goal
        for k, members in self.teams.items():
            if at_end and (len(members) == self.n or (self.cfg.home_slots and not self._blind(members, p))):
                self._targets[members] = home[members]
                continue
            ref, heading = self.team_reference(members, p)
            region = intersect_all([[self.common[k], room[k]]])[0] if k in room else self.common[k]
            slots = self._fit(k, region, len(members), ref, heading)
            if slots is None:  # no formation fits: each robot on its own, as [20] breaks the formation; each heads
                # for where the team's shift to p_r takes it, kept inside its own region (towards p_r itself, every
                # robot got the same target and only the local planner kept them apart: 10 contacts per Scenario 2)
                shift = ref - p[members].mean(axis=0)
                alone = [fit_centres(self.regions[i], [np.zeros((1, 2))], p[i] + shift)[0] for i in members]
                slots = np.array([c if c is not None else p[i] for c, i in zip(alone, members, strict=True)])
            perm = assign_slots(p[members], slots)
            self._targets[members] = slots[perm]
        if self.cfg.target_gap > 0:  # ours: no two robots sent to within a body of each other (fallbacks, teams' edges)
            self._targets = separated(self._targets, 2 * self.radius + self.cfg.target_gap)

    def _clear_of_other_teams(self, p: np.ndarray) -> dict[int, Region]:
        """Ours ([20] leaves robots of other teams to the local planner): for each team, the half-planes that keep its
        target formation off the robots of the other teams and off their current targets, grown from the team's centre
        like a region (robots as discs of 2 r + 0.1 m). Without them two subteams fit their formations on top of each
        other round the same p_r."""
        rows = []
        for members in self.teams.values():
            others = np.setdiff1d(np.arange(self.n), members)
            discs = np.concatenate([p[others], self._targets[others]])
            r = np.full(len(discs), self.radius + 0.1)
            rows += grow_halfplanes(
                p[members].mean(axis=0)[None],
                discs,
                discs,
                r,
                self.cfg.visibility,
                self.radius,
                sides=self.cfg.visibility_sides,
            )
        return dict(zip(self.teams, regions_from_halfplanes(rows), strict=True))

    def _fit(self, k: int, region: Region, m: int, ref: np.ndarray, heading: float) -> np.ndarray | None:
        """The feasible template (shape, scale, position) with the least cost: distance of its centre from p_r, plus
        shape_penalty per step away from the preferred shape and for shrinking ([20]'s formation optimisation, over a
        finite set of candidates)."""
        rot = rotation(heading)
        min_scale = (2 * self.radius + 0.1) / self.spacing
        # scales that keep 0.1 m between robots; a team spaced tighter than that keeps its own spacing (no shrinking)
        scales = [s for s in self.cfg.scales if m == 1 or s >= min_scale] or [max(self.cfg.scales)]
        options = [
            (rank, scale, scale * shape @ rot.T, scale * self._hull(shape) @ rot.T)
            for rank, shape in enumerate(self.shapes(m))
            for scale in scales
        ]
        centres = fit_centres(region, [hull for *_, hull in options], ref)
        best, best_cost, choice = None, math.inf, None
        previous = self._choice.get(k)
        for (rank, scale, slots, _), centre in zip(options, centres, strict=True):
            if centre is None:
                continue
            dx, dy = centre - ref
            cost = math.hypot(dx, dy) + self.cfg.shape_penalty * (rank + 1.0 - scale)
            cost += self.cfg.switch_penalty * (previous is not None and previous != (m, rank, scale))
            if cost < best_cost:
                best, best_cost, choice = slots + centre, cost, (m, rank, scale)
        self._choice[k] = choice
        return best
