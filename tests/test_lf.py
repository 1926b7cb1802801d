"""`method=lf`: leader-follower keeps its formation in the open and, by design, gets stuck at a narrow corridor."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import job_dirs
from stafpipe.controllers.base import limit_approach
from stafpipe.launch import launch
from stafpipe.sensing import Observation


def _results(workdir, *overrides) -> pd.DataFrame:
    before = set(job_dirs(workdir))
    assert launch("eval", ["method=lf", "eval.episodes=1", *overrides]) == 0
    [run] = [d for d in job_dirs(workdir) if d not in before]
    return pd.read_parquet(run / "results.parquet")


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_lf_in_the_open_reaches_the_goal_in_formation_near_the_time_bound(workdir) -> None:
    r = _results(workdir, "scenario.obstacles=[]", "formation=wedge").iloc[0]
    assert r.sr == 1.0 and r.collisions == 0
    assert r.tt_ratio < 1.2  # within 20 % of the shortest-path time of the formation centre
    assert r["cfi_0.5"] > 0.85  # formation integrity kept (the corridor-width part of CFI does not apply here)


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_lf_gets_stuck_in_the_corridor_without_collisions(workdir) -> None:
    r = _results(workdir, "scenario.time_limit=60", "world.stuck_time=0").iloc[0]
    assert r.collisions == 0  # the avoidance caps approach speeds: robots stop short of walls and of each other
    assert r.sr < 1.0  # no subteaming, no adaptation: the outer robots wait at the wall (STAF Section 4)
    assert r.duration == pytest.approx(60.0, abs=0.2)  # the stuck rule off: the episode runs to its time limit
    # on (the default): the episode ends once the team has stood still for stuck_time, the same robots short
    stuck = _results(workdir, "scenario.time_limit=60", "world.stuck_time=5").iloc[0]
    assert stuck.sr == r.sr and stuck.duration < 50.0


def _capped_robot_by_robot(v, obs, radius, avoid_distance, avoid_gain, stop_gap):
    """The approach cap as it was written before batching, robot by robot and cap by cap (robots by index, then the
    wall): the reference."""
    out = v.copy()
    dist = np.linalg.norm(obs.rel_position, axis=-1)
    gaps = dist - 2 * radius
    close = obs.neighbours & (gaps < avoid_distance)
    unit = obs.rel_position / np.maximum(dist, 1e-9)[..., None]
    o_dir = obs.obstacle / np.maximum(np.linalg.norm(obs.obstacle, axis=-1, keepdims=True), 1e-9)
    for i in range(len(v)):
        caps = [(unit[i, j], gaps[i, j]) for j in np.flatnonzero(close[i])]
        if obs.obstacle_distance[i] < avoid_distance:
            caps.append((o_dir[i], obs.obstacle_distance[i]))
        for normal, gap in caps:
            excess = float(out[i] @ normal) - avoid_gain * (gap - stop_gap)
            if excess > 0:
                out[i] -= excess * normal
    return out


def test_the_approach_cap_of_a_batch_is_each_worlds_bit_for_bit() -> None:
    """`limit_approach` on a batch of worlds gives, in every world, exactly the bits of the cap applied robot by robot
    (L&F and the `avoiding` teacher cap all worlds in one call; results must not depend on the batch): crowded random
    teams, walls close by; a robot with one cap approaches no faster than it allows afterwards."""
    rng = np.random.default_rng(7)
    b, n, radius, reach, gain, stop = 6, 7, 0.2, 0.3, 2.0, 0.02
    pos = rng.uniform(0.0, 2.0, (b, n, 2))
    rel = pos[:, None, :, :] - pos[:, :, None, :]
    neighbours = ~np.eye(n, dtype=bool)[None].repeat(b, 0)
    wall = rng.normal(size=(b, n, 2)) * 0.3
    wall_gap = rng.uniform(0.0, 0.5, (b, n))
    zeros = np.zeros((b, n, 2))
    obs = Observation(
        pos,
        zeros,
        np.zeros((b, n)),
        zeros,
        wall,
        wall_gap,
        neighbours,
        rel,
        np.zeros((b, n, n, 2)),
        np.zeros(b),
        np.zeros((b, 0, 4)),
        neighbours,
    )
    v = rng.normal(size=(b, n, 2))
    batch = limit_approach(v, obs, radius, reach, gain, stop)
    for w in range(b):
        one = obs.world(w)
        assert np.array_equal(batch[w], _capped_robot_by_robot(v[w], one, radius, reach, gain, stop))
        assert np.array_equal(batch[w], limit_approach(v[w], one, radius, reach, gain, stop))
    assert not np.array_equal(batch, v)  # the cap acted
    gaps = np.linalg.norm(rel, axis=-1) - 2 * radius
    toward = np.einsum("bid,bijd->bij", batch, rel / np.maximum(np.linalg.norm(rel, axis=-1), 1e-9)[..., None])
    close = neighbours & (gaps < reach)
    alone = (close.sum(-1) == 1) & (wall_gap >= reach)  # one cap only: it holds afterwards (caps in turn may not)
    assert alone.any()
    held = close & alone[..., None]
    assert (toward[held] <= gain * (gaps[held] - stop) + 1e-9).all()


@pytest.mark.slow  # about 3 s on 2 cores (two 26 s episodes)
def test_orca_takes_a_holonomic_square_round_a_pillar_the_cap_let_touch(workdir) -> None:
    # a square of 9 meets a 1.5 m pillar on its way: the followers keep their slots round the leader and slide along
    # the pillar; the approach cap, one pair at a time, let them graze it (6.4 contacts an episode over 10 episodes)
    pillar = [
        "scenario.team.n=9",
        "formation=square",
        "scenario.obstacles=[{circle: {center: [15, 6], radius: 1.5}}]",
        "scenario.time_limit=60",
    ]
    cap = _results(workdir, *pillar, "method.local_planner=cap").iloc[0]
    auto = _results(workdir, *pillar).iloc[0]  # auto: ORCA for holonomic robots
    assert cap.obstacle_collisions > 0 and cap.sr < 1.0
    assert auto.collisions == 0 and auto.sr == 1.0


def test_lf_takes_orca_for_holonomic_robots_the_cap_for_differential_drive_and_refuses_others() -> None:
    from stafpipe.controllers.base import TeamInfo
    from stafpipe.controllers.lf import LFConfig, LFController
    from stafpipe.errors import ConfigError
    from stafpipe.scenario import ScenarioConfig, build_scenario

    with pytest.raises(ConfigError, match=r"method\.local_planner"):
        LFController(LFConfig(local_planner="mpc"))
    chosen = {}
    for drive in ("holonomic", "diff_drive"):
        spec = ScenarioConfig()
        spec.robot.drive = drive
        scenario = build_scenario(spec)
        slots = scenario.template()
        start, goal = slots + np.array(spec.team.start), slots + np.array(spec.team.goal)
        controller = LFController(LFConfig())
        controller.reset(TeamInfo(scenario, start, goal, slots, np.zeros((0, 2)), 2.4))
        chosen[drive] = (controller.orca, controller.forward)
    assert chosen == {"holonomic": (True, False), "diff_drive": (False, True)}


def test_differential_drive_followers_cap_the_motion_their_drive_makes() -> None:
    """`local_planner=forward` (`auto`'s choice for differential drive since 2026-12-06): the approach cap also on
    the motion the drive makes from the capped command. A line of ten through the corridor, 40 s: the cap alone let
    followers turning towards slots beyond the wall drive into it (177 contact starts), the forward cap 12 and no
    robot contact."""
    import dataclasses

    from stafpipe.controllers.lf import LFConfig, LFController
    from stafpipe.episode import run_episode
    from stafpipe.geometry import Geometry
    from stafpipe.scenario import build_scenario
    from stafpipe.scenario_pool import load_named_scenario
    from stafpipe.sensing import SensingConfig
    from stafpipe.world import WorldConfig

    base = load_named_scenario("corridor").spec
    spec = dataclasses.replace(
        base,
        team=dataclasses.replace(base.team, formation="line"),
        robot=dataclasses.replace(base.robot, drive="diff_drive"),
        time_limit=40.0,
    )
    sc = build_scenario(spec)
    contacts = {}
    for planner in ("cap", "forward"):
        controller = LFController(LFConfig(local_planner=planner))
        result = run_episode(sc, Geometry.of(sc), controller, "lf", 0, WorldConfig(), SensingConfig())
        contacts[planner] = (result["collisions"], result["robot_collisions"])
    assert contacts["cap"][0] > 100 and contacts["forward"][0] < 20 and contacts["forward"][1] == 0
