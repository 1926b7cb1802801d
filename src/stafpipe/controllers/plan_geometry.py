"""Geometry the STAF plan works in (controllers/staf_plan.py): the free width across its path, formation extents,
and targets kept apart (the path's arc-length frame is `geometry.PathFrame`)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from itertools import permutations

import numpy as np

from stafpipe.formations import formation_slots, rotation
from stafpipe.geometry import lengths, obstacle_distance
from stafpipe.highlevel.graphs import radius_adjacency


def extent(slots: np.ndarray, radius: float) -> tuple[float, float]:
    """(depth along the heading, width across it) of formation-frame slots, bodies included."""
    if len(slots) < 2:
        return 2 * radius, 2 * radius
    x, y = slots[:, 0], slots[:, 1]  # np.ptp's max - min, without its wrapper (the plan calls this every step)
    return float(x.max() - x.min()) + 2 * radius, float(y.max() - y.min()) + 2 * radius


def separated(
    points: np.ndarray,
    distance: float,
    rounds: int = 3,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """`points` (n, 2) with every pair closer than `distance` pushed apart along its line, half each (a few rounds
    of pairwise projection; pairs found with a k-d tree, so large teams stay cheap). `bounds` (low, high corners):
    the points are kept inside them in every round, so a push out of the box is undone before the next round and
    the pair is pushed apart along the box's edge instead (clipping only after separating brought two targets at a
    world edge back to 0.12 m apart)."""
    from scipy.spatial import cKDTree

    out = np.array(points, dtype=float)
    if bounds is not None:
        out = np.minimum(np.maximum(out, bounds[0]), bounds[1])  # np.clip's values without its call overhead
    for _ in range(rounds):
        if len(out) <= 32 and not radius_adjacency(out, distance - 1e-9).any():  # most steps: no pair, no tree
            break
        pairs = cKDTree(out).query_pairs(distance - 1e-9, output_type="ndarray")
        if len(pairs) == 0:
            break
        i, j = pairs[:, 0], pairs[:, 1]
        d = out[i] - out[j]
        length = np.linalg.norm(d, axis=1, keepdims=True)
        unit = np.where(length > 1e-9, d / np.maximum(length, 1e-9), [[1.0, 0.0]])
        push = 0.5 * (distance - length) * unit
        np.add.at(out, i, push)
        np.add.at(out, j, -push)
        if bounds is not None:
            out = np.minimum(np.maximum(out, bounds[0]), bounds[1])
    return out


def members(labels: np.ndarray) -> list[np.ndarray]:
    """The robots (index order) of each subteam present in `labels`, in label order: one pass over a plain list (a
    handful of robots, split within a control step: numpy's per-call cost dominated a sort and counts)."""
    by_label: dict[int, list[int]] = {}
    for robot, label in enumerate(labels.tolist()):
        by_label.setdefault(label, []).append(robot)
    return [np.array(by_label[label], dtype=np.intp) for label in sorted(by_label)]


@functools.lru_cache(maxsize=256)
def unit_slots(kind: str, k: int, angle_deg: float) -> np.ndarray:
    """Slots of a k-robot formation at spacing 1 (a single robot: the origin); read-only, computed once per shape
    (the step that splits lays out every subteam: benchmarks/staf_decision_time.py)."""
    slots = np.zeros((1, 2)) if k < 2 else formation_slots(kind, k, 1.0, angle_deg)
    slots.flags.writeable = False
    return slots


def subteam_shape(
    k: int,
    kind: str,
    angle_deg: float,
    spacing: float,
    radius: float,
    file_weights: Callable[[np.ndarray], np.ndarray],
    inside_out: bool = False,
) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """(unit-spacing slots, depth along the path, single-file weights, column ranks) of a k-robot subteam of the STAF
    plan; `file_weights(unit slots)` says where along the path it walks in single file; `inside_out`: `column_rank`'s
    order."""
    unit = unit_slots(kind, k, angle_deg)
    depth = extent(unit * spacing, radius)[0]
    weights = file_weights(unit)
    if weights.any():  # room for the column the subteam becomes in single file
        depth = max(depth, (k - 1) * spacing + 2 * radius)
    rank = column_rank(unit, inside_out)
    weights.flags.writeable = rank.flags.writeable = False  # shared by every subteam of k robots
    return unit, depth, weights, rank


def lateral_clearance(
    points: np.ndarray, heading: np.ndarray, scenario, reach: float = 10.0, step: float = 0.05, both: bool = False
) -> np.ndarray:
    """(P,) free distance from each path point to the nearest obstacle straight across the path (the smaller of the
    left and right sides, up to `reach`): the half-width a formation centred on the path may use. Distance to
    obstacles ahead or behind does not count (a wall behind the goal does not make the goal area narrow).
    `both`: the sum of the two sides instead, the free width across the path wherever the path runs in it."""
    if not scenario.capsules and not scenario.polygons:
        return np.full(len(points), 2 * reach if both else reach)
    normal = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
    offsets = np.arange(0.0, reach + step, step)
    sides = []
    for side in (1.0, -1.0):
        rays = points[:, None] + side * offsets[None, :, None] * normal[:, None]
        blocked = obstacle_distance(rays.reshape(-1, 2), scenario).reshape(len(points), len(offsets)) <= 0.0
        sides.append(np.where(blocked.any(axis=1), offsets[blocked.argmax(axis=1)], reach))
    return sides[0] + sides[1] if both else np.minimum(sides[0], sides[1])


LANE_MARGIN = 0.1
"""m added to a robot's diameter for the lane ahead of it (`blocked_ways`): two robots closer across than 2r + this
cannot pass each other without one giving way; chosen as the plan's `target_gap`, not tuned."""


def blocked_ways(progress: np.ndarray, lateral: np.ndarray, order: list[np.ndarray], radius: float) -> int:
    """How many robots of later subteams stand in the way of robots of earlier ones in a subteam order: more than a
    radius ahead along the path, and less than 2r + LANE_MARGIN across from it (in its lane). The earlier subteam
    moves on while the later ones wait where they are, so such a robot is met head-on."""
    count = 0
    for j in range(len(order) - 1):
        ahead, later = order[j], order[-1] if j + 2 == len(order) else np.concatenate(order[j + 1 :])
        in_front = progress[later][None, :] - progress[ahead][:, None] > radius
        in_lane = np.abs(lateral[later][None, :] - lateral[ahead][:, None]) < 2 * radius + LANE_MARGIN
        count += int((in_front & in_lane).sum())
    return count


def unblocked_order(order: list[np.ndarray], progress: np.ndarray, lateral: np.ndarray, radius: float) -> list:
    """`order` itself if no robot is met head-on in it (`blocked_ways`), else the order of the same subteams with the
    fewest such robots (the first found: ties keep the given order's preference)."""
    if not blocked_ways(progress, lateral, order, radius):
        return order
    return list(min(permutations(order), key=lambda o: blocked_ways(progress, lateral, list(o), radius)))


def column_rank(slots: np.ndarray, inside_out: bool = False) -> np.ndarray:
    """(k,) each robot's place in its subteam's column (0 at the front) from its unit-spacing formation slot (k, 2):
    the slot furthest ahead first, then from left to right, so that blending from the formation does not cross
    ways; `inside_out`: within a row, the slot nearest the path first, then outwards, left before right (a line
    abreast files in like a zip, its ends last)."""
    rank = np.empty(len(slots), dtype=int)
    ahead = -np.round(slots[:, 0], 6)
    keys = (-slots[:, 1], np.round(np.abs(slots[:, 1]), 6), ahead) if inside_out else (-slots[:, 1], ahead)
    rank[np.lexsort(keys)] = np.arange(len(slots))
    return rank


def column_weight(file_weights: np.ndarray, anchor: float, half: float, ds: float) -> float:
    """The largest single-file weight (`file_weights`, sampled every `ds` along the path) over a column of half-length
    `half` centred on arc length `anchor`; 0 where the column lies past the samples."""
    window = file_weights[int(max(0.0, anchor - half) / ds) : int(max(0.0, anchor + half) / ds) + 1]
    return float(np.maximum.reduce(window)) if len(window) else 0.0


def follow_order(
    rank: np.ndarray, progress: np.ndarray, margin: float, until: float = np.inf, lateral: np.ndarray | None = None
) -> np.ndarray:
    """`rank` (k,) with each pair of neighbours in the column swapped while the one placed behind stands more than
    `margin` ahead of the other along the path (`progress` (k,)) and the other has not yet come to `until` (the end
    of the single-file stretch: robots leaving it spread back into their formation and keep their order): the
    column's order becomes the robots' own, so that no robot has to pass another in single file (`plan.reorder`).
    `lateral` (k,): each robot's offset from the path, counted as that much further behind (the way it still has to
    come across to the column's line; `plan.reorder_lateral`). A copy."""
    ahead = progress if lateral is None else progress - np.abs(lateral)
    by_place = np.argsort(rank)
    swapped = True
    while swapped:  # bubble passes: a few robots, each swap removes one inversion, so it ends
        swapped = False
        for i in range(len(by_place) - 1):
            a, b = by_place[i], by_place[i + 1]
            if ahead[b] > ahead[a] + margin and progress[a] < until:
                by_place[i], by_place[i + 1] = b, a
                swapped = True
    out = np.empty_like(rank)
    out[by_place] = np.arange(len(rank))
    return out


def travel_frame(pos: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and goals (n, 2) turned about the origin so that the team heads along +x, from its centre to its
    goal centre (the deep graph cut's `heading` feature). The cut's node features are world-frame vectors (STAF
    Sec. 3: p_i, g_i, q_i) and the network, trained on every heading, is not exactly equivariant; in this frame its
    subteams do not depend on which way the map points (docs/decisions.md, "The cut in the team's travel frame")."""
    d = goal.sum(axis=0) / len(goal) - pos.sum(axis=0) / len(pos)  # the centres (np.mean's sums and divisions)
    turn = rotation(-float(np.arctan2(d[1], d[0]))).T
    return pos @ turn + 0.0, goal @ turn + 0.0  # `place` about the origin: one rotation for both (+ 0.0 as its centre)


def short_of(samples: np.ndarray, clear: np.ndarray, gap: float) -> np.ndarray:
    """(m, 2): along each row of points `samples` (m, k, 2) from a robot to its target, the last point before the first
    whose clearance `clear` (m, k) is below `gap` (the robot's own place if that is the first point)."""
    near = clear < gap
    first = np.where(near.any(axis=1), near.argmax(axis=1), samples.shape[1])
    return samples[np.arange(len(samples)), np.maximum(first - 1, 0)]


def ramp_around(tight: np.ndarray, ds: float, ramp: float) -> np.ndarray:
    """(samples,): 1 at the path samples (`ds` apart) where `tight` holds, falling linearly to 0 over `ramp` metres on
    either side; 0 everywhere if it holds nowhere."""
    where = np.flatnonzero(tight)
    if not len(where):
        return np.zeros(len(tight))
    k = np.arange(len(tight))
    after = np.clip(np.searchsorted(where, k), 0, len(where) - 1)  # nearest tight sample at or after k
    before = np.clip(after - 1, 0, len(where) - 1)
    gap = np.minimum(np.abs(k - where[after]), np.abs(k - where[before])) * ds
    return np.clip(1.0 - gap / max(ramp, 1e-9), 0.0, 1.0)


def clear_arc(frame, clearance, pos: np.ndarray, own: np.ndarray, s: np.ndarray, keep: float) -> np.ndarray:
    """(m,) for robots at `pos` (m, 2): the arc length of the path `frame` (a PathFrame) furthest from their own arc
    lengths `own` (m,) towards `s` (m,), tried every tenth of the way, whose point the robot reaches on a straight way
    that keeps `keep` from the obstacles (`clearance`: points (.., 2) -> distance (..)); `s` where none does."""
    k = 11
    arcs = s[:, None] + (own - s)[:, None] * np.linspace(0.0, 1.0, k)[None]  # (m, k): from s back to own
    aims = frame.at(arcs)[0]
    t = np.linspace(0.0, 1.0, 2 * k)[None, None, :, None]  # 22 points: 0.1 m apart on a way of 2.1 m (1 m ahead)
    ways = pos[:, None, None] + t * (aims[:, :, None] - pos[:, None, None])  # (m, k, 2 k, 2)
    clear = (clearance(ways) >= keep).all(axis=2)
    return arcs[np.arange(len(pos)), np.where(clear.any(axis=1), clear.argmax(axis=1), 0)]


def short_of_ahead(
    targets: np.ndarray, pos: np.ndarray, progress: np.ndarray, labels: np.ndarray, distance: float
) -> np.ndarray:
    """`targets` (n, 2), each within `distance` of a robot of its own subteam further along the path (`progress`)
    moved to `distance` short of the nearest such robot, on the line from it back to the target's own robot."""
    gap = targets[:, None, :] - pos[None, :, :]
    close = (gap * gap).sum(-1)
    close = np.where((progress[None, :] > progress[:, None]) & (labels[None, :] == labels[:, None]), close, np.inf)
    near = close.argmin(1)
    hit = close[np.arange(len(targets)), near] < distance * distance
    if not hit.any():
        return targets
    out = targets.copy()
    back = pos[hit] - pos[near[hit]]
    length = lengths(back, keepdims=True)
    out[hit] = np.where(length > 1e-9, pos[near[hit]] + distance * back / np.maximum(length, 1e-9), targets[hit])
    return out


def stood_still(still: np.ndarray, still_at: np.ndarray, pos: np.ndarray, dt: float, move: float = 0.05) -> np.ndarray:
    """Seconds (n,) each robot has stayed within `move` (m) of where it last moved, updated in place for one step of
    `dt`: a robot further than `move` from `still_at` starts again from where it is now."""
    moved = lengths(pos - still_at) > move
    still[:] = np.where(moved, 0.0, still + dt)
    still_at[moved] = pos[moved]
    return still
