import numpy as np
import pytest

from stafpipe.formations import place
from stafpipe.geometry import obstacle_distance
from stafpipe.paths import conf_dir
from stafpipe.scenario import ScenarioConfig, TeamSpec, WorldBounds, build_scenario, load_scenario_file
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig, Worlds


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


def test_robots_told_to_stand_still_stand_still_in_an_episodes_first_step() -> None:
    # pymunk carries a contact's position correction into the next step: the robots stacked at the origin when a world
    # is built, or pressed into a wall at the end of the last episode, once moved by up to 0.3 m in the first step.
    team = TeamSpec(n=4, formation="line", spacing=1.0, start=[2.0, 2.5], goal=[8.0, 2.5], heading_deg=90)
    sc = build_scenario(ScenarioConfig(name="box", world=WorldBounds(xmax=10.0, ymax=5.0), team=team))
    worlds = Worlds([corridor()])
    worlds.reset([0])
    start = worlds.pos.copy()
    worlds.step(np.zeros((1, 10, 2)))
    assert np.abs(worlds.pos - start).max() < 1e-9
    worlds = Worlds([sc])
    worlds.reset([0])
    for _ in range(60):  # into the wall and each other
        worlds.step(np.full((1, 4, 2), -1.0))
    assert worlds.collided[0].any()
    worlds.reset([1])
    start = worlds.pos.copy()
    worlds.step(np.zeros((1, 4, 2)))
    assert np.abs(worlds.pos - start).max() < 1e-9


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


def test_the_start_perturbation_never_puts_a_robot_on_a_wall_or_a_robot() -> None:
    # A tight line (0.5 m slots, 0.1 m between bodies) with its end robots 0.3 m from the walls: a 0.2 m perturbation
    # would put many of them on each other or the wall; those start on their slots instead.
    team = TeamSpec(n=6, formation="line", spacing=0.5, start=[2.0, 1.55], goal=[8.0, 1.55], heading_deg=0)
    sc = build_scenario(ScenarioConfig(name="box", world=WorldBounds(xmax=10.0, ymax=3.1), team=team))
    r = sc.spec.robot.radius
    moved = 0
    for seed in range(20):
        worlds = Worlds([sc], cfg=WorldConfig(start_noise=0.2))
        worlds.reset([seed])
        pos = worlds.pos[0]
        gaps = np.linalg.norm(pos[:, None] - pos[None], axis=-1)[np.triu_indices(6, 1)]
        assert gaps.min() > 2 * r and obstacle_distance(pos, sc).min() > r
        moved += int((np.linalg.norm(pos - place(sc.template(), np.array(team.start), 0.0), axis=1) > 1e-9).sum())
    assert moved > 20, "the perturbation was dropped for (nearly) every robot"


def test_heading_spread_turns_the_start_formation_and_nothing_else() -> None:
    sc = corridor()
    plain = Worlds([sc], cfg=WorldConfig(start_noise=0.0))
    plain.reset([3])
    turned = Worlds([sc], cfg=WorldConfig(start_noise=0.0, heading_spread_deg=30.0))
    turned.reset([3])
    a, b = plain.pos[0], turned.pos[0]
    assert np.allclose(a.mean(0), b.mean(0)) and np.array_equal(plain.goal, turned.goal)
    # the same shape, turned: pairwise distances kept, positions not
    dist = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    assert np.allclose(dist(a), dist(b)) and np.abs(a - b).max() > 0.05
    angle = np.degrees(np.arctan2(*(b[0] - b.mean(0))[::-1]) - np.arctan2(*(a[0] - a.mean(0))[::-1]))
    assert 0 < abs((angle + 180) % 360 - 180) <= 30
    assert np.allclose(np.degrees(turned.heading[0] - plain.heading[0]), (angle + 180) % 360 - 180)  # facing the turn
    # the spread draws from its own random stream: each robot's start perturbation is the same with or without it
    # and so is the sensing noise on the first observation
    noisy, noisy_turned = (Worlds([sc], cfg=WorldConfig(heading_spread_deg=s)) for s in (0.0, 30.0))
    seen, seen_turned = noisy.reset([3]), noisy_turned.reset([3])
    jitter = noisy.pos[0] - a
    assert np.abs(jitter).max() > 0.01 and np.allclose(noisy_turned.pos[0] - b, jitter)
    assert np.allclose(seen.position - noisy.pos, seen_turned.position - noisy_turned.pos)


def test_episodes_differ_by_default() -> None:
    # Issue 19: with the default start perturbation and sensing noise, seeded episodes of one scenario are not copies.
    runs = [_run(Worlds([corridor()]), [s], steps=30) for s in (0, 1, 2)]
    starts = [Worlds([corridor()]) for _ in range(2)]
    for w, s in zip(starts, (0, 1), strict=True):
        w.reset([s])
    assert np.abs(starts[0].pos - starts[1].pos).max() > 0.1  # centimetres, not millimetres
    seen = [run.position[0] for run in runs]
    assert np.abs(seen[0] - seen[1]).max() > 0.02 and np.abs(seen[1] - seen[2]).max() > 0.02


def test_a_start_kick_moves_each_robot_once_by_at_most_its_size() -> None:
    """`world.start_kick`: the first step carries each robot up to that far (not all the same way), the second step
    with a zero command moves nothing, the same seed kicks the same way, and the default kicks nobody."""
    kicked = Worlds([corridor()] * 2, cfg=WorldConfig(start_kick=0.3))
    kicked.reset([4, 5])
    start = kicked.pos.copy()
    kicked.step(np.zeros((2, 10, 2)))
    moved = kicked.pos - start
    dist = np.linalg.norm(moved, axis=-1)
    assert 0.05 < dist.max() <= 0.3 + 1e-6
    assert np.abs(moved[0] - moved[0].mean(axis=0)).max() > 0.05  # each robot its own way
    after = kicked.pos.copy()
    kicked.step(np.zeros((2, 10, 2)))
    assert np.abs(kicked.pos - after).max() < 1e-9 and np.abs(kicked.vel).max() == 0.0
    again = Worlds([corridor()] * 2, cfg=WorldConfig(start_kick=0.3))
    again.reset([4, 5])
    again.step(np.zeros((2, 10, 2)))
    assert np.array_equal(again.pos, after)
    plain = Worlds([corridor()] * 2)
    plain.reset([4, 5])
    assert np.array_equal(plain.pos, start)  # the kick draws from its own stream: the starts are the same
    plain.step(np.zeros((2, 10, 2)))
    assert np.abs(plain.pos - start).max() < 1e-9
