import numpy as np
import pytest

from stafpipe.paths import conf_dir
from stafpipe.scenario import ScenarioConfig, TeamSpec, build_scenario, load_scenario_file
from stafpipe.sensing import SensingConfig
from stafpipe.world import Worlds


def corridor():
    return build_scenario(load_scenario_file(conf_dir() / "scenario" / "corridor.yaml"))


def _run(worlds, seeds, steps=40):
    worlds.reset(seeds)
    for _ in range(steps):
        obs, _ = worlds.step(1.5 * (worlds.goal - worlds.pos))
    return obs


def test_batch_equals_single_worlds() -> None:
    sensing = SensingConfig(position_noise=0.05, drop_prob=0.2)
    batch = _run(Worlds([corridor()] * 3, sensing), [5, 6, 7])
    for b, seed in enumerate([5, 6, 7]):
        single = _run(Worlds([corridor()], sensing), [seed])
        for field_b, field_s in zip(batch.world(b), single.world(0), strict=True):
            assert np.array_equal(field_b, field_s)


def test_same_seed_same_run_other_seed_other_run() -> None:
    a, b, c = (_run(Worlds([corridor()]), [s]).position for s in (1, 1, 2))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_walls_hold_a_robot_and_the_contact_is_counted() -> None:
    team = TeamSpec(n=2, formation="line", spacing=1.0, start=[2.0, 2.0], goal=[8.0, 2.0], heading_deg=90)
    sc = build_scenario(ScenarioConfig(name="box", team=team))
    worlds = Worlds([sc])
    worlds.reset([0])
    hits = 0
    for _ in range(100):
        _, events = worlds.step(np.array([[[-1.0, -1.0], [-1.0, -1.0]]]))
        hits += len(events[0])
    r = sc.spec.robot.radius
    assert (worlds.pos[0] >= r - 0.03).all(), "robots pushed through the world's walls"
    assert hits >= 1 and worlds.collided[0].all()


def test_holonomic_limits_speed_and_acceleration() -> None:
    worlds = Worlds([corridor()])
    worlds.reset([0])
    worlds.step(np.full((1, 10, 2), 50.0))
    speed = np.linalg.norm(worlds.vel[0], axis=1)
    assert (speed <= 2.0 * 0.1 + 1e-6).all()  # max_accel 2 m/s^2 over one 0.1 s period
    for _ in range(20):
        worlds.step(np.full((1, 10, 2), 50.0))
    assert np.linalg.norm(worlds.vel[0], axis=1).max() <= 1.0 + 1e-6


def test_diff_drive_turns_at_bounded_rate() -> None:
    sc = corridor()
    spec = sc.spec
    spec.robot.drive = "diff_drive"
    worlds = Worlds([build_scenario(spec)])
    worlds.reset([0])
    h0 = worlds.heading[0].copy()
    worlds.step(np.tile([[0.0, 1.0]], (1, 10, 1)))  # command straight left: a quarter turn away
    assert np.allclose(np.abs(worlds.heading[0] - h0), spec.robot.max_turn_rate * 0.1)


def test_moving_obstacle_moves_along_its_waypoints() -> None:
    sc = build_scenario(load_scenario_file(conf_dir() / "scenario" / "zhu_moving_obstacle.yaml"))
    worlds = Worlds([sc])
    worlds.reset([0])
    start = worlds.mover_positions(0)[0].copy()
    for _ in range(10):
        worlds.step(np.zeros((1, 4, 2)))
    assert worlds.mover_positions(0)[0] == pytest.approx(start + [0.8 * 1.0, 0.0], abs=1e-6)


def test_sensing_radius_occlusion_drops_and_obstacle_vector() -> None:
    sc = corridor()
    worlds = Worlds([sc], SensingConfig(radius=2.0, occlusion=True))
    worlds.reset([0])
    worlds.pos[0] = 0.0
    worlds.pos[0, :3] = [[4.0, 6.0], [5.0, 6.0], [6.0, 6.0]]  # 2 hides behind 1, seen from 0
    worlds.pos[0, 3:] = np.stack([np.arange(7) * 1.0 + 20.0, np.full(7, 1.0)], 1)  # far away, near the bottom wall
    obs = worlds.observe().world(0)
    assert obs.neighbours[0, 1] and not obs.neighbours[0, 2]
    assert obs.neighbours[1, 0] and obs.neighbours[1, 2]
    assert obs.obstacle[3] == pytest.approx([0.0, -1.0])  # the wall y = 0 is 1 m below robot 3's centre
    assert obs.obstacle_distance[3] == pytest.approx(1.0 - sc.spec.robot.radius)
    dropped = Worlds([sc], SensingConfig(drop_prob=1.0))
    dropped.reset([0])
    assert not dropped.observe().neighbours.any()
