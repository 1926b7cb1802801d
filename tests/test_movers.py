"""Moving obstacles and STAF (`method.avoid_movers`, docs/journal/2026-12-06-staf-planned-history.md, "Moving
obstacles"): neither STAF's plan nor its
network sees a mover's velocity, so a safety layer (controllers/orca.py `avoid_movers`) steps the robots a walker can
reach out of its way, and leaves every other command as it was."""

from __future__ import annotations

import numpy as np
import pytest

from stafpipe.controllers.orca import ORCA_HORIZON, avoid_movers
from stafpipe.controllers.staf import StafController, StafMethodConfig
from stafpipe.episode import run_episode
from stafpipe.geometry import Geometry
from stafpipe.scenario import MovingObstacle, ScenarioConfig, TeamSpec, WorldBounds, build_scenario
from stafpipe.sensing import Observation, SensingConfig
from stafpipe.world import WorldConfig


def _observation(position: np.ndarray, velocity: np.ndarray, movers: np.ndarray) -> Observation:
    n = len(position)
    rel = position[None] - position[:, None]
    dist = np.linalg.norm(rel, axis=-1)
    return Observation(
        position=position,
        velocity=velocity,
        heading=np.zeros(n),
        goal=position + 5.0,
        obstacle=np.tile([0.0, 9.0], (n, 1)),
        obstacle_distance=np.full(n, 9.0),
        neighbours=(dist < 2.0) & ~np.eye(n, dtype=bool),
        rel_position=rel,
        rel_velocity=velocity[None] - velocity[:, None],
        time=np.zeros(()),
        movers=movers,
        heard=(dist < 2.0) & ~np.eye(n, dtype=bool),
    )


def test_a_robot_a_walker_can_reach_steps_aside_and_the_others_keep_their_command() -> None:
    """A walker 1.2 m ahead coming head-on: the robot's new velocity keeps the two clear for ORCA's horizon; a robot
    10 m away keeps its command to the bit."""
    position = np.array([[0.0, 0.0], [10.0, 10.0]])
    pref = np.array([[1.0, 0.0], [0.7, -0.3]])
    walker = np.array([[1.2, 0.05, -0.8, 0.0]])
    obs = _observation(position, pref.copy(), walker)
    out = avoid_movers(pref, obs, 0.2, 1.0, np.array([0.3]))
    assert np.array_equal(out[1], pref[1])
    assert np.linalg.norm(out[0] - pref[0]) > 0.1 and np.linalg.norm(out[0]) <= 1.0 + 1e-9
    t = np.linspace(0.0, ORCA_HORIZON, 101)[:, None]
    gap = np.linalg.norm(walker[0, :2] + t * walker[0, 2:] - t * out[0], axis=1) - 0.5
    assert gap.min() > 0.0  # with the command as it was they meet within half a second
    assert (np.linalg.norm(walker[0, :2] + t * walker[0, 2:] - t * pref[0], axis=1) - 0.5).min() < 0.0


def _crossing() -> ScenarioConfig:
    """Four robots across an open field; a walker crosses their way at 1.4 m/s and meets them 2.5 m from the start
    (without the safety layer it hits two of them)."""
    return ScenarioConfig(
        name="crossing",
        world=WorldBounds(xmin=0.0, ymin=0.0, xmax=16.0, ymax=10.0),
        moving_obstacles=[MovingObstacle(radius=0.3, speed=1.4, waypoints=[[4.5, 0.5], [4.5, 9.5]], loop=True)],
        team=TeamSpec(n=4, formation="square", spacing=1.0, start=[2.0, 5.0], goal=[13.0, 5.0], heading_deg=0.0),
        time_limit=30.0,
    )


@pytest.mark.slow
def test_staf_keeps_clear_of_a_walker_that_crosses_its_way() -> None:
    """With the safety layer no robot touches the walker in three episodes; without it the walker runs into them."""
    sc = build_scenario(_crossing())
    contacts = {}
    for avoid in (True, False):
        controller = StafController(StafMethodConfig(avoid_movers=avoid))
        runs = [
            run_episode(sc, Geometry.of(sc), controller, "staf_planned", seed, WorldConfig(), SensingConfig(), 0.3, 0.1)
            for seed in range(3)
        ]
        contacts[avoid] = sum(r["collisions"] for r in runs)
        assert all(r["tt"] < 25.0 for r in runs)
        if avoid:
            assert all(r["sr"] == 1.0 for r in runs)
    assert contacts[True] == 0 and contacts[False] > 0


@pytest.mark.slow
def test_leader_follower_on_a_differential_drive_keeps_clear_of_a_walker() -> None:
    """L&F's differential-drive local planner (the approach cap, `forward`) saw a walker as a wall point without its
    velocity and was hit; the walkers are now avoided first (`orca.avoid_movers`), as ORCA avoids them for holonomic
    robots."""
    from stafpipe.controllers.lf import LFConfig, LFController
    from stafpipe.scenario import RobotSpec

    spec = _crossing()
    spec.robot = RobotSpec(drive="diff_drive")
    sc = build_scenario(spec)
    runs = [
        run_episode(sc, Geometry.of(sc), LFController(LFConfig()), "lf", seed, WorldConfig(), SensingConfig(), 0.3, 0.1)
        for seed in range(3)
    ]
    assert sum(r["collisions"] for r in runs) == 0 and all(r["sr"] == 1.0 for r in runs)
