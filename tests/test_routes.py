"""Routes through reference waypoints (`reference_path`): a goal counts only once the route has been passed, and the
methods that follow a path keep their place on a route that comes back near its start (Zhu et al. 2019, Scenario 1:
a loop whose goal lies 0.5 m from its start)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from staf_plans import ideal_run
from stafpipe.controllers.lf import LFConfig, LFController
from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.episode import run_episode
from stafpipe.geometry import Geometry, PathFrame, point_ahead
from stafpipe.metrics import MetricContext, RouteProgress, Trajectory, route_done, success_rate, travel_time
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig

LOOP = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [0.0, 0.5]])
"""A square loop ending 0.5 m from its start."""


def _trajectory(centres: list[tuple[float, float]], goal: np.ndarray) -> Trajectory:
    pos = np.array([[c, (c[0] + 1.0, c[1])] for c in centres], dtype=float)
    steps = len(centres)
    return Trajectory(
        time=0.1 * np.arange(steps),
        positions=pos,
        velocities=np.zeros_like(pos),
        subteams=np.zeros((steps, 2), dtype=int),
        team_goal=goal,
        obstacle_distance=np.full((steps, 2), 5.0),
    )


def _context(route: tuple) -> MetricContext:
    return MetricContext(
        robot_radius=0.2,
        formation="line",
        spacing=1.0,
        angle_deg=90.0,
        heading_deg=0.0,
        passage_width=5.0,
        travel_time_lower_bound=4.0,
        route=route,
    )


def test_a_goal_counts_only_once_the_route_is_passed_in_order() -> None:
    goal = np.array([[0.0, 0.5], [1.0, 0.5]])
    stays = _trajectory([(0.0, 0.0), (0.0, 0.3), (0.0, 0.5), (0.0, 0.5)], goal)  # never leaves the start
    around = _trajectory([(0.0, 0.0), (5.0, 0.0), (5.0, 5.0), (0.0, 0.5)], goal)
    backwards = _trajectory([(0.0, 0.0), (5.0, 5.0), (5.0, 0.0), (0.0, 0.5)], goal)  # the waypoints out of order
    route = ((5.0, 0.0), (5.0, 5.0))
    assert route_done(stays.positions, route) == 4 and route_done(around.positions, route) == 2
    assert route_done(backwards.positions, route) == 4 and route_done(stays.positions, ()) == 0
    assert travel_time(stays, _context(())) == 0.1  # without a route, standing by the goal is arriving
    assert math.isnan(travel_time(stays, _context(route))) and success_rate(stays, _context(route)) == 0.0
    assert math.isclose(travel_time(around, _context(route)), 0.3) and success_rate(around, _context(route)) == 1.0
    assert success_rate(backwards, _context(route)) == 0.0
    # a robot passing within ROUTE_REACH (1 m) counts, the team's centroid being further away
    assert route_done(_trajectory([(4.2, 0.5)], goal).positions, ((5.0, 0.0),)) == 0


def test_a_point_keeps_its_place_on_a_route_that_comes_back_near_itself() -> None:
    frame = PathFrame(LOOP)
    start = np.array([[0.1, 0.3]])  # nearer the loop's end (0, 0.5) than its start
    assert frame.progress(start)[0] > 35.0  # the nearest point of the whole path: the end
    assert frame.progress(start, near=np.zeros(1))[0] < 1.0  # near where it was: the start
    assert frame.progress(start, near=np.array([39.0]))[0] > 35.0
    points, _, left = point_ahead(LOOP, start, 1.0, near=np.zeros(1))
    assert left[0] > 35.0 and points[0][0] > 0.5  # one metre on along the first side, not the end


@pytest.mark.slow
@pytest.mark.slow
def test_leader_follower_goes_round_a_route_that_ends_near_its_start() -> None:
    """Zhu et al.'s Scenario 1: before, the leader's path went straight to the goal 0.5 m away and the team "arrived"
    in under a second; now it follows the circle (about 37 s at 1.5 m/s, the bound 24.5 s)."""
    sc = load_named_scenario("zhu_moving_obstacle")
    result = run_episode(
        sc, Geometry.of(sc), LFController(LFConfig()), "lf", 0, WorldConfig(), SensingConfig(), 0.3, 0.1, None
    )
    assert result["sr"] == 1.0 and result["tt"] > result["tt_lower_bound"] > 20.0


@pytest.mark.slow
def test_staf_plan_goes_round_a_route_that_ends_near_its_start() -> None:
    """The plan alone (robots step straight to their targets) on Zhu et al.'s Scenario 1: with each robot's progress
    kept near its last (`plan.track_progress`) the team goes round and home; with the nearest point of the whole path
    the robots at the start were put at the loop's end, and the team stalled short of it."""
    sc = load_named_scenario("zhu_moving_obstacle")
    never = lambda pos, goal, m: np.zeros(len(pos), dtype=int)  # noqa: E731 (four robots never split)
    tracked, _, _ = ideal_run(sc, never, steps=700)
    assert 30.0 < tracked < 60.0
    nearest, _, _ = ideal_run(sc, never, steps=700, plan_cfg=PlanConfig(track_progress=False))
    assert math.isinf(nearest)


def test_route_progress_step_by_step_agrees_with_route_done() -> None:
    """The arrival bonus's route check (`RouteProgress`, one step at a time) passes the route at the sample SR's
    `route_done` finds, on random walks round a three-waypoint route."""
    rng = np.random.default_rng(3)
    route = [(2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]
    for _ in range(20):
        walk = np.cumsum(rng.normal(0.0, 0.4, (200, 3, 2)), axis=0) + rng.normal(0.0, 0.5, (1, 3, 2))
        progress = RouteProgress([route])
        first = next((t for t in range(len(walk)) if progress.update(walk[t : t + 1])[0]), len(walk))
        assert first == route_done(walk, route)


@pytest.mark.slow
def test_the_arrival_bonus_waits_for_the_route() -> None:
    """Zhu et al.'s loop, whose goal slots lie 0.5 m from the start: robots that step straight onto them get no
    arrival bonus in the multi-agent environment (nor the trainer, the same `step_reward`), the team has not gone
    round."""
    from stafpipe.marl_env import BatchedTeamEnv

    env = BatchedTeamEnv("zhu_moving_obstacle", worlds=1, method="dgnn", episode_steps=40)
    env.reset(0)
    for _ in range(40):
        to_goal = env.adapter.goals() - env.worlds.pos
        c, s = np.cos(env.worlds.heading), np.sin(env.worlds.heading)
        local = np.stack([c * to_goal[..., 0] + s * to_goal[..., 1], -s * to_goal[..., 0] + c * to_goal[..., 1]], -1)
        env.step(np.clip(2.0 * local / env.worlds.robot.max_speed, -1.0, 1.0))
    assert (env.dist < 0.3).all()  # every robot on its goal slot
    assert not env.reached.any()
