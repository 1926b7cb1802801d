"""STAF's hand-written rules (methods/staf/subteaming.py): known answers for m, balance, goals, order and regroup."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stafpipe.formations import formation_slots, place
from stafpipe.geometry import PathFrame
from stafpipe.methods.staf.subteaming import (
    SubteamingConfig,
    SubteamPlan,
    balanced_labels,
    carried_goal,
    subteam_count,
    teacher_aim,
)


@pytest.mark.parametrize(
    ("kind", "n", "eta", "m"),
    [
        # Table 1's corridor, 2.4 m (2.37 m on the clearance grid): ten robots do not fit at 0.6 m spacing with
        # 0.1 m to each wall, five of a circle or a wedge do (widths 1.37 and 2.10 m, bodies included), five abreast
        # do not (2.80 m) and neither do four (2.20 m against 2.17 m of room): the line needs four subteams
        ("circle", 10, 2.37, 2),
        ("wedge", 10, 2.37, 2),
        ("line", 10, 2.37, 4),
        # 3.2 m: five abreast fit (2.80 m against 3.00 m), ten circle robots too (2.25 m): no cut for the circle
        ("line", 10, 3.2, 2),
        ("circle", 10, 3.2, 1),
        ("wedge", 10, 3.2, 2),
        # STAF Fig. 11(c): nine in line through 3 m passages divide into three
        ("line", 9, 2.97, 3),
    ],
)
def test_the_number_of_subteams_is_the_smallest_whose_formations_fit(kind, n, eta, m):
    assert subteam_count(SubteamingConfig(), kind, n, eta, 0.2, 90.0) == m


def test_a_fixed_number_of_subteams_keeps_two_robots_a_subteam():
    assert subteam_count(SubteamingConfig(m=3), "line", 10, 1.0, 0.2, 90.0) == 3
    assert subteam_count(SubteamingConfig(m=4), "line", 6, 1.0, 0.2, 90.0) == 3


def test_balanced_labels_take_the_most_probable_balanced_division():
    # argmax would give seven robots to subteam 0; the balanced division moves the two least sure of it
    y = np.array([[0.9, 0.1]] * 5 + [[0.6, 0.4], [0.55, 0.45]] + [[0.1, 0.9]] * 3)
    assert np.bincount(y.argmax(axis=1)).tolist() == [7, 3]
    labels = balanced_labels(y, 2)
    assert np.bincount(labels).tolist() == [5, 5]
    assert labels[:5].tolist() == [0] * 5 and labels[5:].tolist() == [1] * 5
    assert sorted(np.bincount(balanced_labels(np.full((10, 3), 1 / 3), 3)).tolist()) == [3, 3, 4]


def test_a_carried_goal_keeps_the_goal_formation_and_turns_with_the_route():
    goal = place(formation_slots("wedge", 5, 1.0), (20.0, 0.0), 0.0)
    frame = PathFrame(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [20.0, 10.0]]))
    along = goal[:, 0] - goal[:, 0].mean()  # each slot's place along the team's heading (x)
    level = 13.0 + along  # in formation, centred three metres up the second leg
    for cfg, ahead in ((SubteamingConfig(), 2.0), (SubteamingConfig(lead=0.4), 0.4)):
        target, centre = carried_goal(level, 13.0, frame, goal, cfg, 0.0)
        assert np.allclose(centre, [10.0, 3.0 + ahead])  # `lookahead` (or `lead`) ahead of the formation's centre
        turned = (goal - goal.mean(axis=0)) @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # the formation turned by 90 deg
        assert np.allclose(target - centre, turned)
        assert np.array_equal(carried_goal(np.full(5, 29.0), 29.0, frame, goal, cfg, 0.0)[0], goal)  # near the end
    # a robot far behind its place sets its target round the route point `lookahead` ahead of that place
    behind = level.copy()
    behind[4] -= 5.0
    own = 13.0 - 5.0 + 2.0  # its progress less its slot's offset, two metres on: 10 m, the corner
    target, centre = carried_goal(behind, 12.0, frame, goal, SubteamingConfig(), 0.0)
    assert np.allclose(centre[4], [10.0, own - 10.0]) and np.allclose(centre[:4], [10.0, 4.0])
    target, centre = carried_goal(behind, 12.0, frame, goal, SubteamingConfig(lead=0.4), 0.0)
    assert np.allclose(centre[4], [10.0, own - 10.0]) and np.allclose(centre[:4], [10.0, 2.4])


def test_with_a_lead_a_robot_ahead_of_its_place_sees_its_goal_closer_and_one_behind_further():
    """With `lead`, the moving formation closes its errors: every target is `lead` ahead of its slot round its centre,
    so the distance to it is `lead` less the robot's error along the way (a step towards it slows or hurries)."""
    goal = place(formation_slots("wedge", 5, 0.6), (30.0, 0.0), 0.0)
    frame = PathFrame(np.array([[0.0, 0.0], [40.0, 0.0]]))
    cfg = SubteamingConfig(lookahead=2.0, lead=0.4)
    along = goal[:, 0] - goal[:, 0].mean()
    error = np.array([0.3, 0.0, -0.5, 0.0, 0.2])  # ahead of its place positive
    pos = np.stack([10.0 + along + error, goal[:, 1]], axis=1)
    target, _ = carried_goal(pos[:, 0], 10.0, frame, goal, cfg, 0.0)
    assert np.allclose(target[:, 0] - pos[:, 0], 0.4 - error)
    assert np.allclose(target[:, 1], goal[:, 1])


def test_the_teacher_aims_clear_of_the_walls_and_in_sight():
    frame = PathFrame(np.array([[0.0, -1.0], [10.0, -1.0]]))

    def open_above(points):  # a wall at y >= 1
        return 1.0 - points[..., 1]

    # a target in the wall: pulled towards its route point until 0.3 m is left (every 0.15 m), in sight
    pos, target, centre = np.array([[0.0, 0.0]]), np.array([[2.0, 1.5]]), np.array([[2.0, 0.0]])
    aim = teacher_aim(pos, target, centre, np.array([0.0]), frame, open_above, 0.2, 0.3)
    assert aim[0] == pytest.approx([2.0, 0.6])
    assert teacher_aim(pos, centre, centre, np.array([0.0]), frame, open_above, 0.2, 0.3)[0].tolist() == [2.0, 0.0]

    def thin_wall(points):  # the half-line x = 1, y >= 0
        dx, dy = points[..., 0] - 1.0, np.minimum(points[..., 1], 0.0)
        return np.sqrt(dx * dx + dy * dy)

    # a target beyond the wall: the route point furthest ahead that the robot reaches in a straight line
    pos, target = np.array([[0.5, 0.5]]), np.array([[3.0, 0.5]])
    aim = teacher_aim(pos, target, target, np.array([0.5]), frame, thin_wall, 0.2, 0.3)
    assert aim[0] == pytest.approx([1.1, -1.0])


def test_the_teacher_shrinks_a_subteam_as_a_whole():
    """Two robots either side of their route point, one target in the wall: alone, only that one is pulled in (the
    pair's shape lost); as one subteam both are pulled by the same factor (the shape kept, smaller)."""
    frame = PathFrame(np.array([[0.0, 0.0], [10.0, 0.0]]))

    def band(points):  # walls at y = +-1
        return 1.0 - np.abs(points[..., 1])

    pos = np.array([[0.0, 0.4], [0.0, -0.2]])
    target, centre = np.array([[2.0, 1.2], [2.0, -0.6]]), np.full((2, 2), [2.0, 0.0])
    alone = teacher_aim(pos, target, centre, np.zeros(2), frame, band, 0.2, 0.3)
    assert alone[0] == pytest.approx([2.0, 0.6]) and alone[1] == pytest.approx([2.0, -0.6])
    together = teacher_aim(pos, target, centre, np.zeros(2), frame, band, 0.2, 0.3, np.array([0, 0]))
    assert together[0] == pytest.approx([2.0, 0.6]) and together[1] == pytest.approx([2.0, -0.3])


def _corridor_plan(take_turns: bool) -> SubteamPlan:
    start = place(formation_slots("line", 6, 1.0), (0.0, 0.0), 0.0)
    goal = place(formation_slots("line", 6, 1.0), (20.0, 0.0), 0.0)
    path = np.array([[0.0, 0.0], [20.0, 0.0]])

    def cut(s, g, m):  # the left three in one subteam
        return np.array([[0.9, 0.1]] * 3 + [[0.1, 0.9]] * 3)

    cfg = SubteamingConfig(take_turns=take_turns)
    return SubteamPlan(cfg, "line", 90.0, 1.0, 0.2, 0.0, start, goal, path, ((8.0, 12.0),), 2.0, cut)


def test_subteams_enter_in_turn_and_regroup_once_all_are_through():
    plan = _corridor_plan(take_turns=True)
    assert plan.m == 2 and np.bincount(plan.labels).tolist() == [3, 3]
    assert [e[0] for e in plan.drain_events()] == ["split"]
    # each subteam's goal: a line of three, side by side round the team's goal centre
    for k in range(2):
        slots = plan.goal[plan.labels == k]
        assert np.allclose(slots[:, 0], 20.0) and np.allclose(np.sort(np.diff(np.sort(slots[:, 1]))), 1.0)
    start = plan.hold.copy()
    waiting = plan.labels == plan.order[1]
    target = plan.step(start)
    assert np.array_equal(target[waiting], start[waiting])  # the second subteam stands where it is
    assert (target[~waiting, 0] > 1.0).all()  # the first goes
    first_in = start.copy()
    first_in[~waiting, 0] = 8.5  # the first subteam has entered the passage: the second goes
    assert (plan.step(first_in)[waiting, 0] > 1.0).all()
    assert not plan.regrouped
    through = start.copy()
    through[:, 0] = 12.5
    plan.step(through)
    assert plan.regrouped and plan.labels.tolist() == [0] * 6
    assert np.array_equal(plan.goal, place(formation_slots("line", 6, 1.0), (20.0, 0.0), 0.0))
    assert [e[0] for e in plan.drain_events()] == ["merge"]


def test_without_turns_every_subteam_goes_at_once():
    plan = _corridor_plan(take_turns=False)
    target = plan.step(plan.hold.copy())
    assert (target[:, 0] > 1.0).all()
    assert math.isclose(float(plan.expected[0, 1]), 1.0)
