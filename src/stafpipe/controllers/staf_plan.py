"""STAF's execution plan (STAF, Sec. 3 and App. B.2): where every robot should be now.

The team travels as one formation along its planned path (TeamInfo.path). When a passage ahead is too narrow for the
whole team, the high level (deep graph cut, `highlevel/`) divides it into m subteams (m=auto: the smallest m whose
subteams fit, STAF Sec. 7). Each subteam takes the team's formation type with its own robots (Sec. 3's "adaptation
within the same type"), and the subteams pass the narrow part one after another. Once every robot has passed into
space large enough for the full team, every robot's target becomes its own goal slot (Sec. 3, low level): the regroup.
The plan gives targets, subteam labels and the pair distances d_ij of R^adp; the learned low level drives the robots.
The same numpy code runs in PPO training and in `method=staf_planned`. Decisions: docs/staf_planned.md.
"""

from __future__ import annotations

import math

import numpy as np

from stafpipe.controllers import plan_geometry as geo
from stafpipe.controllers.plan_config import SIGHT_REACH, SIGHT_STEP, WAY_CLEARANCE, PlanConfig
from stafpipe.controllers.plan_geometry import column_rank, extent
from stafpipe.formations import assign_slots, place
from stafpipe.geometry import PathFrame, lengths, obstacle_distance


class StafPlan:
    """The plan of one episode: call `reset` with the team, then `step` once per control step."""

    def __init__(
        self,
        cfg: PlanConfig,
        scenario,
        template: np.ndarray,
        goal: np.ndarray,
        path: np.ndarray,
        passage_width: float,
        divide,
    ) -> None:
        """`divide(pos, goal, m) -> labels` is the high level (so tests and training can pass any partitioner)."""
        spec = scenario.spec
        self.cfg, self.goal_slots, self.divide, self.scenario = cfg, np.asarray(goal, float), divide, scenario
        self.kind, self.angle = spec.team.formation, spec.team.angle_deg
        self.spacing, self.radius = spec.team.spacing, spec.robot.radius
        self.max_speed, self.n = spec.robot.max_speed, len(goal)
        self.goal = self.goal_slots.copy()
        """Each robot's goal slot; reassigned to the robots at the regroup (Hungarian): robots are alike."""
        self.frame = PathFrame(path, extend=cfg.extend_path)
        w, keep = spec.world, self.radius + cfg.margin  # `in_world`: targets a radius and the margin off its edge
        self.bounds = (np.array([w.xmin + keep, w.ymin + keep]), np.array([w.xmax - keep, w.ymax - keep]))
        # the way into the goal area (the path's chord over its last 2 m): robots going home enter their slots along it
        chord = self.frame.path[-1] - self.frame.at(max(0.0, self.frame.length - 2.0))[0]
        self.way_in = chord / max(float(np.linalg.norm(chord)), 1e-9)
        # free space across the path every 0.1 m: where the full team fits, and how far subteams must shrink
        self.ds = 0.1
        points, heading = self.frame.at(np.arange(0.0, self.frame.length + self.ds, self.ds))
        from stafpipe.geometry import Geometry

        key = ("lateral_clearance", points.tobytes(), heading.tobytes())  # the same path every episode: once
        self.geometry = Geometry.of(scenario)
        self.clear = self.geometry.remember(key, lambda: geo.lateral_clearance(points, heading, scenario))
        self.full_slots = np.asarray(template, float)
        _, full_width = extent(self.full_slots, self.radius)
        narrow = 2 * (self.clear - cfg.margin) < full_width
        self.narrow_start = float(np.argmax(narrow) * self.ds) if narrow.any() else math.inf
        self.narrow_end = float((len(narrow) - 1 - np.argmax(narrow[::-1])) * self.ds) if narrow.any() else -math.inf
        self.m_wanted = self._m_wanted(passage_width) if narrow.any() else 1
        # the whole team walks in single file only where it will not split (it splits before the narrow part)
        alone = narrow.any() and self.m_wanted <= 1
        self.file_weight = self._file_weights(self.full_slots / self.spacing) if alone else self.clear * 0.0
        # a k-robot subteam's layout depends on k alone: worked out once per episode, not in the step that splits
        shape = (self.kind, self.angle, self.spacing, self.radius, self._file_weights, self.cfg.inside_out)
        self.subteam_shapes = [geo.subteam_shape(k, *shape) for k in range(self.n + 1)] if self.m_wanted > 1 else []
        self.reset()

    def _file_weights(self, unit: np.ndarray) -> np.ndarray:
        """(path samples,) how far a formation of unit-spacing slots `unit` must be a column there (0..1): 1 where it
        does not fit the free width at the smallest spacing, ramping down over `file_ramp` metres on either side."""
        if not self.cfg.single_file or len(unit) < 2:
            return np.zeros(len(self.clear))
        smallest = extent(unit * (2 * self.radius + self.cfg.min_gap), self.radius)[1]
        return geo.ramp_around(2 * (self.clear - self.cfg.margin) < smallest, self.ds, self.cfg.file_ramp)

    def _m_wanted(self, eta: float) -> int:
        from stafpipe.highlevel.partition import choose_m

        if self.cfg.m != "auto":
            return min(int(self.cfg.m), max(1, self.n - 1))
        most = min(4, max(1, self.n - 1))
        return choose_m(self.kind, self.n, eta, self.radius, self.cfg.safe_gap, most, self.angle)[0]

    def reset(self) -> None:
        self.labels = np.zeros(self.n, dtype=int)
        self.order: list[np.ndarray] = [np.arange(self.n)]  # robots of each subteam, leading subteam first
        self.slots = [self.full_slots / self.spacing]  # unit-spacing slots, row k for order[0][k]
        self.anchor = np.full(1, -1.0)  # set from the team's progress at the first step
        self.split_done, self.regrouped, self.merging = False, False, False
        self.hold: list[np.ndarray | None] = [None]
        self.file_weights = [self.file_weight]  # per subteam: where it walks in single file
        self.ranks = [column_rank(self.slots[0], self.cfg.inside_out)]  # per subteam: each robot's column place
        self.goal = self.goal_slots.copy()
        self.events: list[tuple[str, list[int], str]] = []
        self.targets = self.goal.copy()
        # the way home at the regroup: each robot's target slides from where it was to its goal slot
        self.home_from = np.zeros((self.n, 2))
        self.home_via = np.zeros((self.n, 2))  # the way home: home_from -> home_via -> goal (via = from: straight)
        self.home_frac, self.home_rate = np.zeros(self.n), np.zeros(self.n)
        self.homing = np.zeros(self.n, dtype=bool)
        self.limits: dict[int, float] = {}  # _short_of_taken of the current step, per subteam
        self.weights: dict[tuple[int, float], float] = {}  # _file_weight of the current step, per subteam and anchor
        self.forms: dict[tuple[int, float], float] = {}  # formation depth per subteam and spacing (`_depth`)
        # the way into the subteams at the split: targets slide from where the robots were to their new slots
        self.split_from: np.ndarray | None = None
        self.split_frac, self.split_rate = 1.0, 0.0
        self.unseen = np.zeros(self.n)  # seconds each robot's target has been out of its sight (`in_sight`)
        self.still = np.zeros(self.n)  # seconds each robot has stayed within 5 cm of `still_at` (`end_wait`)
        self.still_at = np.full((self.n, 2), np.inf)
        self.tracked = np.zeros(self.n)  # each robot's progress a step before (`track_progress`): the start at first

    # -- the plan ---------------------------------------------------------------------------------------------
    def step(self, pos: np.ndarray, dt: float) -> np.ndarray:
        """Targets (n, 2) for robots at `pos` (n, 2) after one control step of `dt` seconds."""
        targets = self._step(pos, dt)
        if self.cfg.target_gap > 0:
            inside = self.bounds if self.cfg.in_world and self.cfg.separate_in_world else None
            targets = geo.separated(targets, 2 * self.radius + self.cfg.target_gap, bounds=inside)
        if self.cfg.short_of_ahead > 0 and self.split_done and not self.regrouped:  # subteams on their way
            progress = self.frame.progress(pos)
            targets = geo.short_of_ahead(targets, pos, progress, self.labels, 2 * self.radius + self.cfg.short_of_ahead)
        if self.cfg.in_sight:
            targets = self._in_sight(pos, targets, dt)
        if self.cfg.in_world:  # np.clip's values without its call overhead (a cost of every control step)
            targets = np.minimum(np.maximum(targets, self.bounds[0]), self.bounds[1])
        return targets

    def _in_sight(self, pos: np.ndarray, targets: np.ndarray, dt: float) -> np.ndarray:
        """`targets`, each one the robot has not seen for `plan.sight_wait` seconds (its straight way crosses an
        obstacle) replaced by the path's point at the target's arc length, held within `SIGHT_REACH` of the robot's
        own (the path keeps clear of obstacles, so the robot goes round the wall along it). A robot sliding round a
        bollard sees its target again sooner, and keeps it."""
        way = targets - pos
        length = lengths(way)
        # a way inside the robot's free disc is in sight; the others are checked point by point (two grid cells of
        # margin: the grid's nearest-cell error at both ends, so the result is the same as checking all)
        blocked = self.geometry.clearance(pos) < length + SIGHT_STEP / 2 + 2 * self.geometry.resolution
        out = targets.copy()
        if blocked.any():
            k = int(min(200, max(2, length[blocked].max() / SIGHT_STEP + 1)))
            samples = pos[blocked, None] + np.linspace(0.0, 1.0, k)[None, :, None] * way[blocked, None]
            clear = self.geometry.clearance(samples)
            rows = np.flatnonzero(blocked)
            crossed = (clear < SIGHT_STEP / 2).any(axis=1)
            blocked[rows] = crossed
            if self.cfg.hold_short > 0:  # while it waits, a target behind an obstacle is held short of it
                out[rows[crossed]] = geo.short_of(samples[crossed], clear[crossed], self.radius + self.cfg.hold_short)
        self.unseen = np.where(blocked, self.unseen + dt, 0.0)
        lost = self.unseen >= self.cfg.sight_wait - 1e-9
        if lost.any():
            own = self.frame.progress(pos[lost])
            s = np.clip(self.frame.progress(targets[lost]), own - SIGHT_REACH, own + SIGHT_REACH)
            if self.cfg.sight_clear:  # not across a wall's corner
                keep = self.radius + max(self.cfg.hold_short, WAY_CLEARANCE)
                s = geo.clear_arc(self.frame, self.geometry.clearance, pos[lost], own, s, keep)
            out[lost] = self.frame.at(s)[0]
        return out

    def _step(self, pos: np.ndarray, dt: float) -> np.ndarray:
        self.limits, self.weights = {}, {}
        if self.regrouped:
            return self._home(dt)
        progress = self.tracked = self.frame.progress(pos, self.tracked if self.cfg.track_progress else None)
        if self.anchor[0] < 0:
            self.anchor[0] = progress.sum() / self.n  # the mean (np.mean's own sum and division, no wrapper)
            if self.cfg.start_slots:
                self._take_start_slots(pos)
        if not self.split_done and progress.sum() / self.n >= self.narrow_start - self.cfg.split_distance:
            self._split(pos, progress)
        passed = progress > self.narrow_end + self.radius
        if self.split_done and not self.merging and (passed.all() or self.anchor[0] >= self.frame.length):
            self._start_regroup(pos)
        if self.merging and passed.all():
            self._finish_regroup(pos)
            return self._home(dt)
        self._release(progress)
        self._advance(progress, dt)
        if self.cfg.reorder:
            self._follow_order(progress, pos)
        if not self.split_done and self.anchor[0] >= self.frame.length:  # never split: the path's end is the goal
            self._finish_regroup(pos)
            return self._home(dt)
        self._place()
        self._slide_into_subteams(dt)
        if self.merging:  # robots that are through head for their goal slots; the others still follow their subteam
            passed = passed | self._stopped_short() | self._held_at_end(pos, dt)
            self._start_home(passed, pos)
            self.labels[passed] = 0
            return self._home(dt)
        return self.targets

    def _take_start_slots(self, pos: np.ndarray) -> None:
        """`plan.start_slots`: robots take the team's slots laid along the path nearest to them (Hungarian)."""
        perm = assign_slots(pos, place(self.full_slots, *self.frame.at(self.anchor[0])))
        self.slots[0] = self.full_slots[perm] / self.spacing
        self.ranks[0] = column_rank(self.slots[0], self.cfg.inside_out)

    def _split(self, pos: np.ndarray, progress: np.ndarray) -> None:
        self.split_done = True
        if self.m_wanted <= 1:
            return
        cut_pos, cut_goal = geo.travel_frame(pos, self.goal) if self.cfg.cut_frame == "travel" else (pos, self.goal)
        labels = np.asarray(self.divide(cut_pos, cut_goal, self.m_wanted), dtype=int)
        if self.cfg.balance:
            from stafpipe.highlevel.partition import balance_sizes

            labels = balance_sizes(labels, pos, self.m_wanted)
        teams = geo.members(labels)
        # the subteam furthest ahead and nearest the path passes first (a line abreast: the middle ones first)
        lateral = self.frame.lateral(pos, progress)
        teams.sort(key=lambda idx: -(progress[idx].sum() / len(idx) - np.abs(lateral[idx]).sum() / len(idx)))  # means
        if self.cfg.unblock:  # unless a waiting robot stands in the way of one that goes before it
            teams = geo.unblocked_order(teams, progress, lateral, self.radius)
        anchors: list[float] = []
        self.order, self.slots, self.file_weights, self.ranks = [], [], [], []
        last_depth = 0.0
        for idx in teams:  # a column along the path: the front subteam just ahead of the team, the others behind
            unit, depth, weights, rank = self.subteam_shapes[len(idx)]
            self.file_weights.append(weights)
            a = (
                progress.max() + depth / 2
                if not anchors
                else anchors[-1] - (last_depth + depth) / 2 - self.cfg.follow_gap
            )
            perm = assign_slots(pos[idx], place(unit * self.spacing, *self.frame.at(a)))
            self.order.append(idx)
            self.slots.append(unit[perm])  # robot idx[k] takes slot perm[k]
            self.ranks.append(rank[perm])  # = column_rank(self.slots[-1]): the slots' ranks go with them
            anchors.append(a)
            last_depth = depth
        self.labels = np.zeros(self.n, dtype=int)
        for j, idx in enumerate(self.order):
            self.labels[idx] = j
        self.anchor = np.array(anchors)
        self.weights, self.forms = {}, {}  # of the subteams before the split
        # later subteams wait where they are, in their own formation (the subteam's type, facing along the path)
        self.hold = [None] + [self._formed(j, pos) for j in range(1, len(self.order))]
        self.split_from, self.split_frac, self.split_rate = pos.copy(), 0.0, 0.0
        self.events.append(("split", list(range(self.n)), f"m={len(self.order)} sizes={[len(i) for i in self.order]}"))

    def _slide_into_subteams(self, dt: float) -> None:
        """After the split the targets slide from where the robots were to their subteam slots, all the same fraction
        of the way, the farthest at top speed: as at the regroup (`_start_home`), jumping targets sent neighbours at
        full speed on converging ways (measured on the doorway: two robots 0.95 m apart closed to contact)."""
        if self.split_from is None or self.split_frac >= 1.0:
            return
        if self.split_rate == 0.0:
            self.split_rate = self._top_speed_rate(np.linalg.norm(self.targets - self.split_from, axis=1))
        self.split_frac = min(1.0, self.split_frac + self.split_rate * dt)
        self.targets = self.split_from + self.split_frac * (self.targets - self.split_from)

    def _formed(self, j: int, pos: np.ndarray) -> np.ndarray:
        """Waiting targets of subteam j: its formation at the team's spacing, centred on the subteam's centroid and
        facing along the path there (STAF Sec. 3: each subteam keeps the formation type with its own robots)."""
        idx = self.order[j]
        centre = pos[idx].sum(axis=0) / len(idx)  # means as np.mean takes them, without its wrapper's cost
        _, heading = self.frame.at(float(self.frame.progress(centre[None])[0]))
        slots = place(self.slots[j] * self.spacing, (0.0, 0.0), heading)
        return slots - slots.sum(axis=0) / len(slots) + centre

    def _start_regroup(self, pos: np.ndarray) -> None:
        """Every robot past the last narrow stretch, or the front subteam at the path's end: goal slots reassigned."""
        self.merging = True
        if len(self.order) > 1:
            self.goal = self.goal_slots[assign_slots(pos, self.goal_slots)]
            self.events.append(("regroup", list(range(self.n)), f"m={len(self.order)}"))

    def _finish_regroup(self, pos: np.ndarray) -> None:
        self.regrouped = True
        self.labels = np.zeros(self.n, dtype=int)
        self._start_home(np.ones(self.n, dtype=bool), pos)

    def _start_home(self, robots: np.ndarray, pos: np.ndarray) -> None:
        """Robots (mask) not yet on their way home start now, together: their targets slide along straight lines to
        their goal slots, all arriving at once, the farthest at the robot's top speed (no later than rushing). Sliding
        together keeps two robots' relative position a blend of where they were and where their slots are; rushing
        each robot to its slot at full speed let ways converge (on the bridge: 0.62 m apart closed to contact)."""
        new = robots & ~self.homing
        if not new.any():
            return
        if self.cfg.home == "departure":  # the free slots go to every robot not yet home-bound, from its target
            waiting = np.flatnonzero(~self.homing)
            self.goal[waiting] = self.goal[waiting][assign_slots(self.targets[waiting], self.goal[waiting])]
        self.home_from[new] = self.targets[new]  # from where each target is now: no target jumps
        self.home_via[new] = self._approach(self.targets[new], self.goal[new])
        self.home_frac[new] = 0.0
        self.home_rate[new] = self._top_speed_rate(self._home_legs(new)[2])
        self.homing |= new

    def _approach(self, start: np.ndarray, slot: np.ndarray) -> np.ndarray:
        """Via points (k, 2) of targets going home from `start` to `slot`: `home_approach` behind the slot along the
        way in where the target is further behind than that and the point is free of obstacles; else `start`."""
        if self.cfg.home_approach <= 0:
            return start.copy()
        via = slot - self.cfg.home_approach * self.way_in
        behind = (slot - start) @ self.way_in > self.cfg.home_approach
        free = obstacle_distance(via, self.scenario) > self.radius + self.cfg.margin
        return np.where((behind & free)[:, None], via, start)

    def _home_legs(self, robots: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lengths of the two legs of each way home (from -> via, via -> goal) and their sum, for `robots`."""
        first = np.linalg.norm(self.home_via[robots] - self.home_from[robots], axis=1)
        second = np.linalg.norm(self.goal[robots] - self.home_via[robots], axis=1)
        return first, second, first + second

    def _top_speed_rate(self, lengths: np.ndarray) -> float:
        """Fraction of the way per second for targets sliding together along ways of these lengths (split and
        regroup slides): the one with the longest way moves at the robot's top speed."""
        return self.max_speed / max(float(lengths.max()), 1e-6)

    def _home(self, dt: float) -> np.ndarray:
        """Advance the robots on their way home one step; their targets."""
        h = self.homing
        self.home_frac[h] = np.minimum(1.0, self.home_frac[h] + self.home_rate[h] * dt)
        if self.cfg.home_approach <= 0:  # straight, exactly as trained (the shipped policy's recipe)
            self.targets[h] = self.home_from[h] + self.home_frac[h, None] * (self.goal[h] - self.home_from[h])
            return self.targets
        first, second, length = self._home_legs(h)
        along = (self.home_frac[h] * length)[:, None]  # distance covered along the two legs
        leg1 = self.home_from[h] + along / np.maximum(first, 1e-9)[:, None] * (self.home_via[h] - self.home_from[h])
        leg2 = self.home_via[h] + (along - first[:, None]) / np.maximum(second, 1e-9)[:, None] * (
            self.goal[h] - self.home_via[h]
        )
        self.targets[h] = np.where(along <= first[:, None], leg1, leg2)
        return self.targets

    def _spacing(self, j: int, s: float) -> float:
        """Spacing of subteam j around arc length s: the team's (adapt=nominal), or (adapt=geometric) the team's shrunk
        to fit the clearance ahead and behind."""
        if self.cfg.adapt == "nominal":
            return self.spacing
        depth, width = extent(self.slots[j] * self.spacing, self.radius)
        lo, hi = int(max(0.0, s - depth) / self.ds), int((s + depth + 1.0) / self.ds) + 1
        clear = float(self.clear[lo:hi].min()) if hi > lo and lo < len(self.clear) else math.inf
        unit_width = width - 2 * self.radius
        if unit_width <= 1e-9 or not math.isfinite(clear):
            return self.spacing
        fit = (2 * (clear - self.cfg.margin) - 2 * self.radius) * self.spacing / unit_width
        return float(np.clip(fit, 2 * self.radius + self.cfg.min_gap, self.spacing))

    def _release(self, progress: np.ndarray) -> None:
        """A waiting subteam starts once every robot of the subteam ahead is `follow_gap` ahead of all of its own."""
        for j in range(1, len(self.order)):
            if (
                self.hold[j] is not None
                and self.hold[j - 1] is None
                and progress[self.order[j - 1]].min() >= progress[self.order[j]].max() + self.cfg.follow_gap
            ):
                self.hold[j] = None
                self.anchor[j] = max(self.anchor[j], float(progress[self.order[j]].sum() / len(self.order[j])))

    def _advance(self, progress: np.ndarray, dt: float) -> None:
        cap = self.frame.length
        for j, idx in enumerate(self.order):
            if self.hold[j] is not None:
                continue
            s = self.anchor[j] + self.cfg.speed * dt
            lead_from = progress[idx].sum() / len(idx)  # the mean
            if self.cfg.lead_past_end:  # column slots the path's end cuts short do not hold the anchor back
                lead_from += self._cut_at_end(j)
            s = min(s, lead_from + self.cfg.max_lead)
            if j > 0 and not self.merging:  # behind the subteam ahead, with room for both formations' depths
                ahead_depth = self._depth(j - 1, self._spacing(j - 1, self.anchor[j - 1]))
                own_depth = self._depth(j, self.spacing)
                s = min(s, self.anchor[j - 1] - (ahead_depth + own_depth) / 2 - self.cfg.follow_gap)
            elif j > 0 and self.cfg.home_approach > 0:  # merging: short of the slots taken by robots gone home
                s = min(s, self._short_of_taken(j))
            self.anchor[j] = min(max(self.anchor[j], s), cap)

    def _cut_at_end(self, j: int) -> float:
        """Mean length (m) by which the path's end cuts short the column slots of subteam j (`_place` puts places at
        arc lengths past the end on the end point), weighted by how far the subteam is a column: its robots' mean
        progress stays that far behind its anchor however well they keep their slots."""
        weight = self._file_weight(j)
        if weight == 0.0:
            return 0.0
        return weight * float(np.maximum(self._column_arcs(j) - self.frame.length, 0.0).sum() / len(self.order[j]))

    def _short_of_taken(self, j: int) -> float:
        """The furthest subteam j's anchor may go while merging: its front `follow_gap` behind the nearest goal slot
        taken by a robot on its way home, where its robots' ways to the free slots are clear (no limit otherwise: on
        along the path, as trained). Once per step."""
        if j not in self.limits:
            self.limits[j] = math.inf
            if self.homing.any() and self._clear_ways(self.targets[self.order[j]], self.goal[~self.homing]):
                taken = float(self.frame.progress(self.goal[self.homing]).min()) - self.radius
                half = self._depth(j, self._spacing(j, self.anchor[j])) / 2
                self.limits[j] = taken - half - self.cfg.follow_gap
        return self.limits[j]

    def _clear_ways(self, starts: np.ndarray, slots: np.ndarray) -> bool:
        """Whether every way home from `starts` to any of `slots` (through its via point) keeps clear of obstacles."""
        if not len(starts) or not len(slots):
            return True
        a = np.repeat(starts, len(slots), axis=0)
        b = np.tile(slots, (len(starts), 1))
        via = self._approach(a, b)
        t = np.linspace(0.0, 1.0, 12)[:, None, None]
        points = np.concatenate([a + t * (via - a), via + t * (b - via)]).reshape(-1, 2)
        return bool((obstacle_distance(points, self.scenario) > self.radius + WAY_CLEARANCE).all())

    def _stopped_short(self) -> np.ndarray:
        """(n,) robots of subteams that have come as far as `_short_of_taken` allows: they start for home from there."""
        out = np.zeros(self.n, dtype=bool)
        if self.cfg.home_approach <= 0:
            return out
        for j in range(1, len(self.order)):
            if self.hold[j] is None and self.anchor[j] >= self._short_of_taken(j) - 1e-6:
                out[self.order[j]] = True
        return out

    def _held_at_end(self, pos: np.ndarray, dt: float) -> np.ndarray:
        """(n,) robots on their targets, or standing still for `end_wait` (`end_home`), in subteams whose anchor is at
        the path's end: nothing moves them on, so they start for home from there."""
        out = np.zeros(self.n, dtype=bool)
        if not self.cfg.end_home:
            return out
        stalled = geo.stood_still(self.still, self.still_at, pos, dt) >= self.cfg.end_wait if self.cfg.end_wait else out
        for j, idx in enumerate(self.order):
            if self.hold[j] is None and self.anchor[j] >= self.frame.length - 1e-6:
                out[idx] = (np.linalg.norm(pos[idx] - self.targets[idx], axis=1) < self.radius) | stalled[idx]
        return out

    def _depth(self, j: int, spacing: float) -> float:
        """Depth of subteam j along the path: its formation's, lengthened where it turns into a column."""
        form = self.forms.get((j, spacing))
        if form is None:  # the subteam's slots only change order after the split (`_follow_order`): the same extent
            form = self.forms[(j, spacing)] = extent(self.slots[j] * spacing, self.radius)[0]
        column = (len(self.order[j]) - 1) * self.spacing + 2 * self.radius
        weight = self._file_weight(j)
        return (1 - weight) * form + weight * max(form, column)

    def _place(self) -> None:
        for j, idx in enumerate(self.order):
            if self.hold[j] is not None:
                self.targets[idx] = self.hold[j]
                continue
            spacing = self._spacing(j, self.anchor[j]) if self.split_done else self.spacing
            self.targets[idx] = place(self.slots[j] * spacing, *self.frame.at(self.anchor[j]))
            weight = self._file_weight(j)
            if weight > 0:
                column = self.frame.at(self._column_arcs(j))[0]  # places past the path's end fall on it
                self.targets[idx] = (1 - weight) * self.targets[idx] + weight * column

    def _column_arcs(self, j: int) -> np.ndarray:
        """Arc lengths of subteam j's column places: centred on its anchor, at the team's spacing, in `ranks[j]`'s
        order (`column_rank`, then `_follow_order`)."""
        return self.anchor[j] + ((len(self.order[j]) - 1) / 2 - self.ranks[j]) * self.spacing

    def _follow_order(self, progress: np.ndarray, pos: np.ndarray) -> None:
        """Moving subteams that are a column take their robots' order along the path (`plan.reorder`): two robots
        that swap places in the column swap their formation slots too, so that the column spreads back into the
        formation without crossing ways. `plan.reorder_lateral`: robots coming in take places by their offsets from
        the path too while the subteam turns into a column, slots once it is one (side by side they would cross)."""
        lateral: np.ndarray | None = None
        for j, idx in enumerate(self.order):
            if self.hold[j] is not None or self._file_weight(j) < (1e-9 if self.cfg.reorder_lateral else 1.0):
                continue
            whole = np.flatnonzero(self.file_weights[j] >= 1.0)  # where it is a column
            side = None
            if self.cfg.reorder_lateral:  # offsets from the path: once a step, where a subteam turns into a column
                lateral = self.frame.lateral(pos, progress) if lateral is None else lateral
                side = lateral[idx] * (progress[idx] < whole[0] * self.ds)
            rank = geo.follow_order(self.ranks[j], progress[idx], self.spacing / 2, whole[-1] * self.ds, side)
            if lateral is None and (rank != self.ranks[j]).any():
                self.slots[j] = self.slots[j][np.argsort(self.ranks[j])[rank]]  # the robot (row) at each place before
            elif lateral is not None and self._file_weight(j) >= 1.0:  # slots follow places once it is a column
                self.slots[j] = self.slots[j][np.argsort(column_rank(self.slots[j], self.cfg.inside_out))[rank]]
            self.ranks[j] = rank

    def _file_weight(self, j: int) -> float:
        """How far subteam j is turned into a column (0..1): the largest single-file weight along its column. Kept
        for the step (`weights`): the plan asks it several times per step, mostly at the same anchor."""
        anchor = float(self.anchor[j])
        if (j, anchor) not in self.weights:
            half = (len(self.order[j]) - 1) / 2 * self.spacing
            self.weights[(j, anchor)] = geo.column_weight(self.file_weights[j], anchor, half, self.ds)
        return self.weights[(j, anchor)]

    @property
    def same(self) -> np.ndarray:
        """(n, n) True where two robots are in the same subteam (n x n: built on demand, not every step)."""
        return self.labels[:, None] == self.labels[None, :]

    @property
    def expected(self) -> np.ndarray:
        """(n, n) d_ij of R^adp (STAF Sec. 3): the distance between two robots' targets, i.e. between their slots in
        their subteam's formation (shrunk with adapt=geometric, nominal with adapt=nominal; blended into a column in
        single file) or, at the regroup, between their targets sliding to the goal slots (same-subteam pairs used)."""
        return np.linalg.norm(self.targets[:, None] - self.targets[None], axis=-1)

    def drain_events(self) -> list[tuple[str, list[int], str]]:
        out, self.events = self.events, []
        return out
