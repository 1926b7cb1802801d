"""STAF's plan safeguards: robots held at the path's end start home (`plan.end_home`), a target behind a wall moves
onto the path (`plan.in_sight`) on a way clear of the wall's corner (`plan.sight_clear`), a column takes its robots'
order along the path (`plan.reorder`) and targets stay inside the world (`plan.in_world`, `plan.separate_in_world`),
and a column longer than the way left to the goal still reaches the path's end (`plan.lead_past_end`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from staf_plans import ideal_run, scenario_with, start_and_plan
from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.controllers.plan_geometry import column_rank, follow_order
from stafpipe.geometry import obstacle_distance
from stafpipe.highlevel.infer import divider
from stafpipe.scenario import build_scenario, load_scenario_file
from stafpipe.scenario_pool import load_named_scenario


def _map(tmp_path, text: str):
    """A scenario from the YAML `text`, read as a user's scenario file is."""
    (tmp_path / "map.yaml").write_text(text)
    return build_scenario(load_scenario_file(tmp_path / "map.yaml"))


def _no_split(pos, goal, m):
    """A partitioner that keeps the team whole (for tests of what the plan does before any split)."""
    return np.zeros(len(pos), dtype=int)


_EXIT_TURN = """
name: exit-turn
world: {xmin: 0.0, ymin: 0.0, xmax: 18.26, ymax: 11.22}
obstacles:
  - box: {center: [9.13, 1.623], size: [11.26, 3.245]}
  - box: {center: [9.13, 8.716], size: [11.26, 5.008]}
team: {n: 8, formation: line, spacing: 1.0, start: [1.5, 5.61], goal: [16.76, 5.778], heading_deg: 0.0}
time_limit: 120.0
"""
"""A 3 m corridor whose exit turns towards a goal 1 m off its axis: the free width across the path is narrow up to
0.23 m before the path's end (a generated map on which two robots of the front subteam waited for ever)."""


@pytest.mark.parametrize("end_home", [False, True])
def test_robots_held_at_the_path_end_start_home(tmp_path, end_home) -> None:
    """`plan.end_home`: where the narrow stretch reaches to the path's end, the front subteam's rear robots (a column
    of five) can never pass it; with end_home they start for home from their slots once they stand on them."""
    sc = _map(tmp_path, _EXIT_TURN)

    def five_three(pos, goal, m):  # the split of the episode that waited: robots 3-7 in front, 0-2 behind
        return (np.arange(len(pos)) < 3).astype(int)

    cfg = PlanConfig(end_home=end_home, in_sight=False)
    _, plan = start_and_plan(sc, five_three, cfg)
    assert plan.frame.length - 0.3 < plan.narrow_end < plan.frame.length  # the map's condition: narrow to the end
    tt, log, _ = ideal_run(sc, five_three, plan_cfg=cfg)
    assert log["events"] == ["split", "regroup"]
    assert math.isfinite(tt) == end_home


@pytest.mark.parametrize("end_wait", [2.0, 0.0])
def test_a_robot_held_at_the_path_end_short_of_its_target_starts_home_after_standing_still(tmp_path, end_wait) -> None:
    """`plan.end_wait`: a robot of a subteam at the path's end that cannot reach its target (0.4 m off it, where robots
    already home stand) starts for home once it has stood still for `end_wait` seconds, not before; the robots on
    their targets start at once (`end_home`). With 0 it waits for ever (a generated bridge ending 2 m from the
    world's edge: 3 of 11 robots stood there for the rest of the episode)."""
    sc = _map(tmp_path, _EXIT_TURN)
    _, plan = start_and_plan(sc, _no_split, PlanConfig(end_wait=end_wait))
    plan.anchor[:] = plan.frame.length
    pos = plan.targets.copy()
    pos[0] += (0.4, 0.0)
    started = [plan._held_at_end(pos, 0.1) for _ in range(25)]
    assert all(s[1:].all() for s in started)
    first = next((k for k, s in enumerate(started) if s[0]), None)
    assert first == (20 if end_wait else None)  # 2 s of 0.1 s steps after the first, which sets where it stands


@pytest.mark.parametrize("wait", [2.0, 0.5])
def test_a_target_behind_a_wall_moves_onto_the_path_ahead_of_the_robot(wait) -> None:
    """`plan.in_sight`: a robot beside the corridor's mouth whose target lies inside the corridor (the wall between
    them) aims at the path instead once the target has been out of sight for `plan.sight_wait` seconds, no more than
    1 m ahead of its own place on it; a robot that sees its target keeps it. (Without `hold_short`, tested below, the
    target stays where it is while the robot waits; `sight_clear`, tested below, may aim nearer.)"""
    sc = load_named_scenario("corridor")
    team, plan = start_and_plan(sc, divider(), PlanConfig(sight_wait=wait, hold_short=0.0, sight_clear=False))
    (cx, cy), (w, h) = sc.spec.obstacles[1]["box"]["center"], sc.spec.obstacles[1]["box"]["size"]  # the upper wall
    outside = np.array([cx - w / 2 - 0.5, cy - h / 2 + 1.0])  # before the wall's face, above the corridor's mouth
    inside, _ = plan.frame.at(plan.frame.progress(outside[None])[0] + 3.0)
    pos, target = team.copy(), team.copy()  # the rest of the team stands on its targets
    pos[:2], target[:2] = [outside, inside - [0.5, 0.0]], [inside, inside + [0.5, 0.0]]
    assert obstacle_distance(pos[:2], sc).min() > sc.spec.robot.radius
    for _ in range(round(wait / 0.1) - 1):  # out of sight not yet long enough: still its own target
        assert plan._in_sight(pos, target, 0.1) == pytest.approx(target)
    out = plan._in_sight(pos, target, 0.1)
    assert out[1:] == pytest.approx(target[1:])  # in sight: unchanged
    assert obstacle_distance(out[:1], sc)[0] > sc.spec.robot.radius  # on the path, clear of the walls
    assert plan.frame.progress(out[:1])[0] == pytest.approx(plan.frame.progress(pos[:1])[0] + 1.0, abs=1e-6)
    assert plan.frame.lateral(out[:1])[0] == pytest.approx(0.0, abs=1e-6)
    target[0] = pos[0] - [0.5, 0.0]  # in sight again: its own target at once
    assert plan._in_sight(pos, target, 0.1) == pytest.approx(target)


def test_follow_order_swaps_only_robots_standing_the_other_way_round() -> None:
    """`plan.reorder`: a column's neighbours swap places where the one placed behind stands more than the margin ahead
    along the path; within the margin (robots side by side) the order stays."""
    rank = np.array([0, 1, 2, 3])
    assert follow_order(rank, np.array([1.0, 3.0, 2.0, 0.0]), 0.2).tolist() == [2, 0, 1, 3]
    assert follow_order(rank, np.array([3.0, 3.1, 2.0, 2.15]), 0.2).tolist() == [0, 1, 2, 3]
    assert follow_order(np.array([3, 2, 1, 0]), np.array([0.0, 1.0, 2.0, 3.0]), 0.2).tolist() == [3, 2, 1, 0]
    # past the stretch's end (1.5) robot 0 keeps its place; robot 3 passes robot 2, which has not come to it
    assert follow_order(rank, np.array([2.0, 3.0, 0.0, -1.0]), 0.2, until=1.5).tolist() == [0, 1, 2, 3]
    assert follow_order(rank, np.array([2.0, 3.0, 0.0, 1.0]), 0.2, until=1.5).tolist() == [0, 1, 3, 2]
    # `plan.reorder_lateral`: a row level along the path, the robot placed first 1.5 m out to the side and the last
    # on the path: the distance across counts as distance behind, so the one on the path leads
    level, side = np.array([4.0, 4.0, 4.0]), np.array([1.5, -0.8, 0.05])
    assert follow_order(rank[:3], level, 0.5).tolist() == [0, 1, 2]
    assert follow_order(rank[:3], level, 0.5, lateral=side).tolist() == [2, 1, 0]
    assert follow_order(rank[:3], level, 0.5, lateral=np.array([0.4, -0.2, 0.0])).tolist() == [0, 1, 2]  # margin
    # from a wedge's slots: the tip first, then left to right
    assert column_rank(np.array([[0.0, 0.0], [-1.0, 1.0], [-1.0, -1.0]])).tolist() == [0, 1, 2]
    # a line abreast (left at +y): left to right, or (`plan.inside_out`) the middle first, then outwards, left first
    line = np.array([[0.0, -2.0], [0.0, -1.0], [0.0, 0.0], [0.0, 1.0], [0.0, 2.0]])
    assert column_rank(line).tolist() == [4, 3, 2, 1, 0]
    assert column_rank(line, inside_out=True).tolist() == [4, 2, 0, 1, 3]
    assert column_rank(np.array([[0.0, 0.0], [-1.0, 1.0], [-1.0, -1.0]]), inside_out=True).tolist() == [0, 1, 2]


def _five_behind(pos, goal, m):  # the split of an episode on the exit-turn map: robots 0-4 wait, 5-7 go first
    return (np.arange(len(pos)) < 5).astype(int)


def test_a_column_placed_the_other_way_round_follows_its_robots(tmp_path) -> None:
    """`plan.reorder`: a subteam in single file (five robots abreast do not fit the 3 m corridor) whose column order
    is the reverse of where its robots stand gets targets in their own order, so no robot has to pass another;
    without it the front target goes to the robot at the back."""
    sc = _map(tmp_path, _EXIT_TURN)
    for reorder in (False, True):
        pos, plan = start_and_plan(sc, _five_behind, PlanConfig(reorder=reorder))
        plan.step(pos, 0.1)
        j = next(j for j in range(len(plan.order)) if plan.file_weights[j].any())  # a subteam that goes in file
        idx = plan.order[j]
        s = plan.frame.length / 2
        plan.hold[j], plan.anchor[j], plan.split_frac = None, s, 1.0  # moving, in file, slid into its subteam
        plan.file_weights[j] = np.ones_like(plan.file_weights[j])  # (shared by equal-sized subteams: not in place)
        plan.ranks[j] = np.arange(len(idx))  # robot idx[0] in front ...
        slots = plan.slots[j].copy()
        behind = plan.frame.at(s - 1.0 * np.arange(len(idx))[::-1])[0]  # ... but standing at the back
        pos[idx] = behind
        plan.tracked = plan.frame.progress(pos)  # the robots put there, not walked there (`plan.track_progress`)
        targets = plan._step(pos, 0.0)[idx]
        order = np.argsort(-plan.frame.progress(targets))  # robots from the front target to the back one
        assert (order.tolist() == list(range(len(idx) - 1, -1, -1))) == reorder
        # the formation slots go with the places: the column spreads back into the formation in the same order
        assert np.array_equal(column_rank(slots), np.arange(len(idx)))  # (the line's slots, in that order)
        assert np.array_equal(column_rank(plan.slots[j]), plan.ranks[j])
        assert np.array_equal(plan.slots[j], slots) != reorder


def test_targets_stay_inside_the_world(tmp_path) -> None:
    """`plan.in_world`: behind a start 1.5 m from the world's edge the rear subteam's column (five robots) reaches
    back beyond the edge; with in_world every target keeps a radius and the margin from it."""
    sc = _map(tmp_path, _EXIT_TURN)
    keep = sc.spec.robot.radius + PlanConfig().margin
    for in_world in (False, True):
        pos, plan = start_and_plan(sc, _five_behind, PlanConfig(in_world=in_world))
        lowest = np.inf
        for _ in range(100):  # robots straight to their targets at 1 m/s
            target = plan.step(pos, 0.1)
            lowest = min(lowest, float(target[:, 0].min()))
            way = target - pos
            pos = pos + way * np.minimum(1.0, 0.1 / np.maximum(np.linalg.norm(way, axis=1, keepdims=True), 1e-9))
        assert (lowest >= sc.spec.world.xmin + keep - 1e-9) == in_world


_DOOR_NEAR_GOAL = """
name: door-near-goal
world: {xmin: 0.0, ymin: 0.0, xmax: 28.29, ymax: 13.41}
obstacles:
  - box: {center: [20.045, 2.925], size: [0.463, 5.85]}
  - box: {center: [20.045, 10.485], size: [0.463, 5.85]}
team: {n: 12, formation: wedge, spacing: 1.0, start: [3.268, 6.705], goal: [25.022, 6.829], heading_deg: 0.0}
time_limit: 144.9
"""
"""A 1.7 m door 5 m before the goal of a 12-robot wedge (a generated map on which the front subteam, a column of nine,
stood still with its last robot in the door for the rest of the episode)."""


@pytest.mark.parametrize("lead_past_end", [False, True])
def test_a_column_longer_than_the_way_left_reaches_the_paths_end(tmp_path, lead_past_end) -> None:
    """`plan.lead_past_end`: the column's front slots are cut short at the path's end, so its robots' mean progress
    stops growing; counted from the anchor, the lead limit then held the anchor short of the end (no regroup, the
    last robot in the door for ever); counted from the slots, the anchor reaches the end and the team gets home."""
    sc = _map(tmp_path, _DOOR_NEAR_GOAL)

    def nine_three(pos, goal, m):  # the split of the episodes that waited: robots 6, 8 and 10 behind
        return np.isin(np.arange(len(pos)), [6, 8, 10]).astype(int)

    cfg = PlanConfig(lead_past_end=lead_past_end)
    tt, log, _ = ideal_run(sc, nine_three, steps=600, plan_cfg=cfg)
    assert log["events"][0] == "split" and ("regroup" in log["events"]) == lead_past_end
    assert math.isfinite(tt) == lead_past_end


_CORRIDOR_NORTH = """
name: corridor-north
world: {xmin: -12, ymin: 0, xmax: 0, ymax: 30}
obstacles:
  - box: {center: [-2.4, 15], size: [4.8, 6]}
  - box: {center: [-9.6, 15], size: [4.8, 6]}
team: {n: 10, formation: wedge, spacing: 1.0, start: [-6.0, 4.0], goal: [-6.0, 26.0], heading_deg: 90}
robot: {radius: 0.2, max_speed: 1.0, max_accel: 2.0, drive: holonomic}
time_limit: 120
"""
"""The Table-1 corridor with a wedge, turned a quarter turn anticlockwise: the team heads north, not east."""


@pytest.mark.parametrize("cut_frame", ["world", "travel"])
def test_the_cut_gives_the_same_subteams_whichever_way_the_map_points(tmp_path, cut_frame) -> None:
    """`plan.cut_frame`: the deep graph cut's features are world-frame vectors, so in the world's axes the shipped
    cut divides the wedge heading north otherwise than the same wedge heading east; in the team's travel frame the
    two get the same subteams (robot i is slot i in both)."""
    divide, cfg = divider(), PlanConfig(cut_frame=cut_frame)
    first = []
    for sc in (scenario_with("corridor", "wedge"), _map(tmp_path, _CORRIDOR_NORTH)):
        _, log, _ = ideal_run(sc, divide, steps=50, plan_cfg=cfg)
        first.append(next(labels for labels in log["labels"] if labels.max() > 0))
    assert np.array_equal(first[0], first[1]) == (cut_frame == "travel")


@pytest.mark.parametrize("start_slots", [False, True])
def test_a_team_facing_away_from_its_path_turns_its_formation_without_crossing(start_slots) -> None:
    """`plan.start_slots`: a wedge facing west with its goal to the east. Robot i kept slot i of the formation laid
    along the path (facing east), so robots were sent through each other (5 % SR, 99 contacts per episode on the
    doorway); taking the nearest slots (min-sum-of-squares, as CAPT), robots moving to their first targets all the
    same fraction of the way stay more than two radii apart."""
    sc = scenario_with("doorway", "wedge")
    sc = build_scenario(dataclasses.replace(sc.spec, team=dataclasses.replace(sc.spec.team, heading_deg=180.0)))
    pos, plan = start_and_plan(sc, _no_split, PlanConfig(start_slots=start_slots))
    way = np.linspace(0.0, 1.0, 101)[:, None, None] * (plan.step(pos, 0.1) - pos) + pos
    closest = (np.linalg.norm(way[:, :, None] - way[:, None], axis=-1) + 9 * np.eye(len(pos))).min()
    assert (closest > 2 * sc.spec.robot.radius) == start_slots, closest


@pytest.mark.parametrize("hold_short", [0.0, 0.15])
def test_a_target_behind_a_wall_is_held_short_of_it_while_the_robot_waits(hold_short) -> None:
    """`plan.hold_short`: a robot 1.5 m before the corridor's wall whose target lies inside the wall. Before the
    `sight_wait` is over, its target is held on its way, at least a radius and `hold_short` from the wall and within
    one checked point (0.1 m) of that; without it the target stays in the wall and the robot presses against it."""
    sc = load_named_scenario("corridor")
    pos, plan = start_and_plan(sc, _no_split, PlanConfig(hold_short=hold_short))
    pos[0] = (10.5, 2.0)  # the wall's face is at x = 12 below y = 4.8
    targets = pos.copy()
    targets[0] = (13.0, 2.0)
    out = plan._in_sight(pos, targets, 0.1)
    assert np.array_equal(out[1:], targets[1:])
    if hold_short == 0:
        assert np.array_equal(out[0], targets[0])
    else:
        gap = obstacle_distance(out[:1], sc)[0] - sc.spec.robot.radius
        assert out[0, 1] == 2.0 and hold_short - 1e-6 <= gap <= hold_short + 0.1 + 1e-6, out[0]


@pytest.mark.parametrize("sight_clear", [False, True])
def test_a_robot_that_lost_sight_of_its_target_aims_where_its_way_clears_the_corner(sight_clear) -> None:
    """`plan.sight_clear`: a robot 0.5 m before the corridor's lower wall, below its corner, whose target lies in the
    wall. Once the target has been out of sight for `sight_wait`, the robot aims at the path: 1 m ahead of its own
    place, on a way that would take its body across the wall's corner; with sight_clear at the furthest point of the
    path up to there whose way keeps a radius and `hold_short` from the walls (to the grid's resolution)."""
    sc = load_named_scenario("corridor")  # the corridor: x 12..18, y 4.8..7.2, the path along y = 6
    team, plan = start_and_plan(sc, _no_split, PlanConfig(sight_clear=sight_clear))
    pos, target = team.copy(), team.copy()  # the rest of the team stands on its targets
    pos[0], target[0] = (11.5, 4.2), (12.8, 4.5)
    for _ in range(round(plan.cfg.sight_wait / 0.1)):
        out = plan._in_sight(pos, target, 0.1)
    assert out[1:] == pytest.approx(target[1:])
    own = plan.frame.progress(pos[:1])[0]
    ahead = plan.frame.progress(out[:1])[0] - own
    way = pos[0] + np.linspace(0.0, 1.0, 200)[:, None] * (out[0] - pos[0])
    closest = obstacle_distance(way, sc).min() - sc.spec.robot.radius
    assert plan.frame.lateral(out[:1])[0] == pytest.approx(0.0, abs=1e-6)  # on the path
    if not sight_clear:
        assert ahead == pytest.approx(1.0) and closest < 0.0  # the body would cross the corner
    else:
        assert 0.0 <= ahead < 1.0 and closest >= plan.cfg.hold_short - plan.geometry.resolution, (ahead, closest)
