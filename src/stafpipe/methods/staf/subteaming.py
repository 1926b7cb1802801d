"""STAF's hand-written decisions, and only those the paper states (the STAF-planned journal (docs/staf_planned.md),
"Every rule and its sentence"):

1. When to cut and into how many subteams (Sec. 7, third limitation): the smallest m such that a subteam of ceil(n/m)
   robots in the team's formation type, at its smallest spacing, fits the narrowest passage of the map (read from the
   occupancy map, App. B.2). m = 1 where the whole team fits: no cut.
2. Who goes with whom: the deep graph cut (Sec. 3, Eq. (1)) on the start and goal positions, its subteam
   probabilities Y turned into hard subteams of balanced sizes (Eq. (1)'s balance term asks n/m robots a subteam;
   ours: a hard constraint, one minimum-cost assignment on -log Y).
3. Each subteam's goal (Sec. 3, low level; Eq. (1)'s subteam-goal centre): its members' mean goal, with goal slots of
   a formation of the same type and spacing of the subteam's size.
4. The regroup (Sec. 3, low level): "once all subteams pass through the narrow corridor into an open area that is
   large enough for the full team", every robot's goal becomes its goal in the full team's formation.
5. The order of entry (`take_turns`; Sec. 4 of Fig. 3: "the first subteam starts moving, followed by the second"): the
   subteam nearest the passage goes first, the next one waits where it stands until every robot of the one before
   has entered.

Everything else (how a subteam keeps, shrinks or stretches its formation, how robots avoid each other and the
walls) is the learned policy's. The goal a robot's network sees is carried along the map's route (`carried_goal`:
ours, not the paper's, whose goals are in sight across open floor; docs/staf_planned.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from stafpipe.errors import require
from stafpipe.formations import assign_slots, formation_slots, place
from stafpipe.geometry import PathFrame
from stafpipe.highlevel.partition import choose_m


@dataclass
class SubteamingConfig:
    """STAF's subteaming and regroup rules (`method.subteaming`, `train_ppo.subteaming`)."""

    high_checkpoint: str = ""
    """The deep graph cut (`stafpipe train-high`); empty: the shipped one. App. B.1: trained first, then fixed."""
    m: int = 0
    """Subteams: 0, the smallest number whose subteams fit the narrowest passage (Sec. 7); > 0, that number."""
    min_spacing: float = 0.6
    """m: the neighbour spacing of a subteam's smallest formation (two bodies of 0.2 m radius and a 0.2 m gap)."""
    wall_margin: float = 0.1
    """m kept free to each side wall for a formation to count as fitting a passage."""
    lookahead: float = 2.0
    """m: how far ahead of a robot's own place on the route its goal is carried at most (`carried_goal`)."""
    lead: float | None = None
    """m: how far ahead of its place in the moving formation a robot's carried goal lies (`carried_goal`); below the
    distance at which a step towards the goal reaches top speed (0.4 with the teacher's gain of 2), a robot ahead of
    its place slows and one behind hurries, so the formation closes its errors while it moves. None (the shipped
    policy's training): `lookahead` ahead of the (sub)team's mean progress. docs/staf_paper.md, "The goal a robot
    sees", says what each measured."""
    take_turns: bool = True
    """Subteams enter the first passage one after another (rule 5); false: all at once."""

    def check(self, key: str) -> None:
        require(self.m >= 0, f"{key}.m", "must be >= 0 (0: chosen by passage width)", self.m)
        require(self.min_spacing > 0, f"{key}.min_spacing", "must be > 0", self.min_spacing)
        require(self.wall_margin >= 0, f"{key}.wall_margin", "must be >= 0", self.wall_margin)
        require(self.lookahead > 0, f"{key}.lookahead", "must be > 0", self.lookahead)
        if self.lead is not None:
            require(0 < self.lead <= self.lookahead, f"{key}.lead", "must be > 0 and <= lookahead", self.lead)


def subteam_count(cfg: SubteamingConfig, kind: str, n: int, eta: float, radius: float, angle_deg: float) -> int:
    """Rule 1: m (at most n // 2, so that every subteam has two robots or more)."""
    if cfg.m:
        return max(1, min(cfg.m, n // 2))
    room = eta - 2 * cfg.wall_margin + 1e-9  # a formation exactly as wide as the room fits
    m, _ = choose_m(kind, n, room, radius, cfg.min_spacing - 2 * radius, max(1, n // 2), angle_deg)
    return m


def balanced_labels(y: np.ndarray, m: int) -> np.ndarray:
    """Rule 2: subteam labels (n,) of sizes floor(n/m) or ceil(n/m) that maximise the product of the graph cut's
    probabilities y (n, >= m): each subteam offers ceil(n/m) places, the first n mod m of them (or all, when m divides
    n) filled in full."""
    n = len(y)
    big, small = n % m or m, m - (n % m or m)
    sizes = [math.ceil(n / m)] * big + [n // m] * small
    places = np.concatenate([np.full(s, j) for j, s in enumerate(sizes)])
    cost = -np.log(np.maximum(y[:, places], 1e-12))
    rows, cols = linear_sum_assignment(cost)
    labels = np.empty(n, dtype=int)
    labels[rows] = places[cols]
    return labels


class SubteamPlan:
    """One world's subteams, their goals and the regroup. `step(pos)` gives every robot's target: its goal slot carried
    along the route; `goal` the slots now, `labels` the subteams, `same` (n, n) who shares a subteam, `expected` (n, n)
    the distances of the formation the robots keep now (R^adp's d_ij)."""

    def __init__(
        self,
        cfg: SubteamingConfig,
        kind: str,
        angle_deg: float,
        spacing: float,
        radius: float,
        heading: float,
        start: np.ndarray,
        goal: np.ndarray,
        path: np.ndarray,
        passages: tuple,
        eta: float,
        cut,
    ) -> None:
        self.cfg, self.kind, self.angle, self.spacing, self.heading = cfg, kind, angle_deg, spacing, heading
        self.frame, self.path = PathFrame(path), path
        self.full_goal = np.asarray(goal, float)
        n = len(goal)
        self.m = subteam_count(cfg, kind, n, eta, radius, angle_deg) if passages else 1
        self.labels = np.zeros(n, dtype=int)
        if self.m > 1:
            y = cut(start, goal, self.m)  # (n, m), or fewer columns where the graph cut offers fewer subteams
            self.m = y.shape[1]
            self.labels = balanced_labels(y, self.m)
        self.entry = passages[0][0] if passages else 0.0
        self.exit = passages[-1][1] if passages else 0.0
        self.progress = self.frame.progress(np.asarray(start, float))
        self.goal = self._subteam_goals(radius) if self.m > 1 else self.full_goal.copy()
        # rule 5: subteams ordered by how far along the way they start; all but the first wait where they stand
        along = [self.progress[self.labels == k].mean() for k in range(self.m)]
        self.order = sorted(range(self.m), key=lambda k: (-along[k], k))
        self.released = 1 if cfg.take_turns else self.m
        self.hold = np.asarray(start, float).copy()
        self.regrouped = self.m == 1
        self.events: list[tuple[str, list[int], str]] = []
        if self.m > 1:
            sizes = np.bincount(self.labels, minlength=self.m).tolist()
            self.events.append(("split", list(range(n)), f"{self.m} subteams of {sizes}"))
        self._update_shape()

    def _subteam_goals(self, radius: float) -> np.ndarray:
        """Rule 3: each subteam's goal slots, a formation of the team's type and spacing of the subteam's size. The
        subteams' formations stand side by side across the team's heading, in the order of their members' mean goals
        (Eq. (1)'s subteam-goal centres) and one spacing apart, round the team's goal centre: the mean goals alone
        put the formations of two interleaved subteams on top of each other. Members take their subteam's slots by the
        least total squared distance from their own goals in the team."""
        across = np.array([-math.sin(self.heading), math.cos(self.heading)])
        order = sorted(range(self.m), key=lambda k: float(self.full_goal[self.labels == k].mean(axis=0) @ across))
        shapes = [formation_slots(self.kind, int((self.labels == k).sum()), self.spacing, self.angle) for k in order]
        widths = [float(np.ptp(s[:, 1])) + 2 * radius for s in shapes]
        total = sum(widths) + self.spacing * (self.m - 1)
        goal, left = self.full_goal.copy(), -total / 2
        centre = self.full_goal.mean(axis=0)
        for k, slots, width in zip(order, shapes, widths, strict=True):
            # formation frame: y to the left, so the first in `order` (rightmost goals) takes the lowest y
            shifted = slots - [0.0, float(slots[:, 1].min()) - radius - left]
            placed = place(shifted, centre, self.heading)
            members = self.labels == k
            goal[members] = placed[assign_slots(self.full_goal[members], placed)]
            left += width + self.spacing
        return goal

    def _update_shape(self) -> None:
        """What stays the same until the next release or the regroup: who waits, who shares a subteam, R^adp's
        distances, and each moving subteam's slot offsets (`slot_offsets`), so that `step` only carries them."""
        waiting = self._waiting()
        self.same = self.labels[:, None] == self.labels[None, :]
        shape = np.where(waiting[:, None], self.hold, self.goal)
        self.expected = np.linalg.norm(shape[:, None] - shape[None], axis=-1) * self.same
        self._moving = []
        for k in np.unique(self.labels[~waiting]):
            members = self.labels == k
            self._moving.append((members, self.goal[members], *slot_offsets(self.goal[members], self.heading)))

    def _waiting(self) -> np.ndarray:
        """(n,) robots of subteams not yet let go (rule 5)."""
        going = np.isin(self.labels, self.order[: self.released])
        return ~going

    def step(self, pos: np.ndarray) -> np.ndarray:
        """(n, 2) targets for robots at `pos` (n, 2)."""
        self.progress = self.frame.progress(pos, near=self.progress)
        changed = False
        while self.released < self.m:  # rule 5: the subteam before has entered the first passage
            ahead = self.labels == self.order[self.released - 1]
            if self.progress[ahead].min() < self.entry:
                break
            self.released += 1
            changed = True
        if not self.regrouped and self.released == self.m and self.progress.min() > self.exit:
            self.regrouped, changed = True, True  # rule 4: every robot is past the last passage
            self.labels = np.zeros(len(pos), dtype=int)
            self.goal = self.full_goal.copy()
            self.events.append(("merge", list(range(len(pos))), "all subteams through: the full team's goals"))
        if changed:
            self._update_shape()
        target = self.hold.copy()
        self.centre = self.hold.copy()  # each robot's (sub)team's carried centre, for the teacher (`free_aim`)
        for members, goal, centre, offset, along in self._moving:
            mine = self.progress[members]
            middle = float(mine.mean())
            if self.cfg.lead is not None:  # the centroid's progress (`carried_goal`)
                middle = float(self.frame.progress(pos[members].mean(axis=0)[None], near=mine.mean()[None])[0])
            target[members], self.centre[members] = carry(
                mine, middle, self.frame, goal, centre, offset, along, self.cfg, self.heading
            )
        return target

    def drain_events(self) -> list[tuple[str, list[int], str]]:
        out, self.events = self.events, []
        return out


def carried_goal(
    progress: np.ndarray, middle: float, frame: PathFrame, goal: np.ndarray, cfg: SubteamingConfig, heading: float
) -> tuple[np.ndarray, np.ndarray]:
    """(k, 2) targets of one (sub)team whose robots are `progress` (k,) along the route `frame`, `middle` along it
    as a whole, with goal slots `goal` (k, 2) of a formation facing `heading` (rad), and (k, 2) the route point each
    target is set round: the slots themselves once `middle` is within `cfg.lookahead` of the route's end; before that,
    each robot's slot offset in the formation, turned to the route's direction, round a route point ahead:

    - `cfg.lead` None (the shipped policy's training): `middle` is the robots' mean progress, and the point is
      `cfg.lookahead` ahead of it, or of the robot's own place (its progress less its slot's offset along the
      route) where that lags behind it. Every robot aims about 2 m ahead and runs at top speed.
    - `cfg.lead` set: `middle` is the centroid's progress, and the point is `cfg.lead` ahead of it, but never more
      than `cfg.lookahead` ahead of the robot's own place. A robot ahead of its place sees its target close (or
      behind it) and slows, one behind sees it further and hurries, so the moving formation corrects its shape. The
      centroid's progress, not the mean of the robots' own: where the route bends, the robots of a wide formation
      across it project onto it unevenly, and a formation standing still across the route can have a mean progress
      `cfg.lead` behind where it stands (a line of nine stood short of its goal).

    Either way the differences between teammates' targets are those of their goal slots (STAF's s_j - s_i compares
    goals); a robot left behind a wall aims along the route from where it is, not at a point beyond the wall; and no
    goal lies round a corner the network cannot see round."""
    return carry(progress, middle, frame, goal, *slot_offsets(goal, heading), cfg, heading)


def slot_offsets(goal: np.ndarray, heading: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`carried_goal`'s parts that depend on the goal slots alone: their centre (2,), each slot's offset from it
    (k, 2) and its place along the way (k,), ahead positive."""
    centre = goal.mean(axis=0)
    offset = goal - centre
    return centre, offset, offset @ [math.cos(heading), math.sin(heading)]


def carry(
    progress: np.ndarray,
    middle: float,
    frame: PathFrame,
    goal: np.ndarray,
    goal_centre: np.ndarray,
    offset: np.ndarray,
    along: np.ndarray,
    cfg: SubteamingConfig,
    heading: float,
) -> tuple[np.ndarray, np.ndarray]:
    """`carried_goal` with the slots' `slot_offsets` computed beforehand."""
    if frame.length - middle <= cfg.lookahead:
        return goal, np.broadcast_to(goal_centre, goal.shape)
    if cfg.lead is None:
        ahead = np.minimum(progress - along, middle) + cfg.lookahead
    else:
        ahead = np.minimum(progress - along + cfg.lookahead, middle + cfg.lead)
    point, direction = frame.at(ahead)
    turn = direction - heading
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    turned = np.concatenate([c * offset[:, :1] - s * offset[:, 1:], s * offset[:, :1] + c * offset[:, 1:]], axis=1)
    return point + turned, point


def teacher_aim(
    pos: np.ndarray,
    target: np.ndarray,
    centre: np.ndarray,
    progress: np.ndarray,
    frame: PathFrame,
    clearance,
    radius: float,
    keep: float,
    labels: np.ndarray | None = None,
) -> np.ndarray:
    """(n, 2) where the imitation teacher drives each robot at `pos` (n, 2): the point nearest its `target` that
    keeps `keep` m from the walls and can be reached in a straight line from the robot without a body touching a
    wall. Candidates, in order: the target pulled towards the route point it is set round (`centre`, from
    `carried_goal`), then route points ever closer ahead of the robot's own `progress`. `clearance(points)` is the
    map's distance to the nearest obstacle: the teacher knows the map, the network does not; the network is left to
    learn how the formation gives way to the walls (R^adp, Sec. 3). With `labels` (n,), the robots of one subteam
    are pulled by one common factor, the least pull that clears all of them, so that the teacher's formation shrinks
    as a whole and keeps its shape; where no common factor clears them all, each robot alone."""
    alpha = np.linspace(1.0, 0.0, 11)
    pulled = centre[:, None] + alpha[:, None] * (target - centre)[:, None]
    ahead = np.minimum(progress[:, None] + np.array([1.5, 1.0, 0.6, 0.3, 0.1]), frame.length)
    along, _ = frame.at(ahead)
    candidates = np.concatenate([pulled, along], axis=1)  # (n, C, 2)
    fraction = np.linspace(0.0, 1.0, 9)[1:]
    line = pos[:, None, None] + fraction[:, None] * (candidates - pos[:, None])[:, :, None]
    clear = clearance(candidates) >= keep
    sight = (clearance(line) >= radius).all(axis=-1)
    ok = clear & sight
    first = np.where(ok.any(axis=1), ok.argmax(axis=1), candidates.shape[1] - 1)
    for team in np.unique(labels) if labels is not None else []:
        members = np.flatnonzero(labels == team)
        common = clear[members, : len(alpha)].all(axis=0)
        if common.any():
            k = int(common.argmax())
            seen = members[sight[members, k]]  # a robot that cannot reach its place in a straight line: alone
            first[seen] = k
    return candidates[np.arange(len(pos)), first]
