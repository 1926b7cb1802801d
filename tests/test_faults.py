"""Faults injected by the world (stafpipe.faults): every method meets them the same way, and the log records them."""

from __future__ import annotations

import numpy as np

from stafpipe.controllers import make_controller
from stafpipe.episode import run_episode
from stafpipe.episode_log import read_episode
from stafpipe.faults import Fault, drop_probability, transitions
from stafpipe.geometry import Geometry
from stafpipe.methods.straight.method import StraightConfig
from stafpipe.paths import conf_dir
from stafpipe.scenario import build_scenario, load_scenario_file
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig, Worlds


def _worlds(*faults: Fault, seeds: tuple[int, ...] = (0,)) -> Worlds:
    scenario = build_scenario(load_scenario_file(conf_dir() / "scenario" / "corridor.yaml"))
    worlds = Worlds([scenario] * len(seeds), SensingConfig(radius=2.0), WorldConfig(faults=list(faults)))
    worlds.reset(list(seeds))
    return worlds


def test_a_stuck_robot_ignores_its_commands_and_stays() -> None:
    worlds = _worlds(Fault(kind="stuck", robot=3, start=1.0))
    push = np.zeros((1, worlds.n, 2))
    push[..., 0] = 0.8
    for _ in range(10):  # until 1 s every robot moves
        worlds.step(push)
    assert worlds.vel[0, 3, 0] > 0.5
    for _ in range(20):  # it stops as fast as its acceleration allows, then stays
        worlds.step(push)
    held = worlds.pos[0, 3].copy()
    for _ in range(20):
        worlds.step(push)
    assert np.allclose(worlds.pos[0, 3], held) and worlds.vel[0, 0, 0] > 0.5


def test_silent_drop_and_dropout_change_what_robots_hear_and_sense() -> None:
    clean = _worlds().observe()
    silent = _worlds(Fault(kind="silent", robot=3)).observe()
    assert np.array_equal(silent.neighbours, clean.neighbours)  # still seen
    others = np.arange(clean.heard.shape[-1]) != 3
    assert clean.heard[0, others, 3].any() and not silent.heard[0, others, 3].any()  # not heard
    assert np.array_equal(silent.heard[0, 3], clean.heard[0, 3])  # it still hears the others
    assert not _worlds(Fault(kind="drop", prob=1.0)).observe().heard.any()
    blind = _worlds(Fault(kind="dropout", robot=3)).observe()
    assert not blind.neighbours[0, 3].any() and blind.obstacle_distance[0, 3] >= 1e3
    assert np.array_equal(blind.heard[0, 3], clean.heard[0, 3])  # sensors dead, radio fine


def test_drop_combines_and_transitions_are_reported_once() -> None:
    faults = [Fault(kind="drop", prob=0.5, start=1.0, end=2.0), Fault(kind="drop", prob=0.5, start=1.5)]
    assert drop_probability(faults, 0.5) == 0.0 and drop_probability(faults, 1.7) == 0.75
    began = [f for kind, f in transitions(faults, 0.9, 1.0) if kind == "fault"]
    ended = [f for kind, f in transitions(faults, 1.9, 2.0) if kind == "fault_end"]
    assert began == faults[:1] and ended == faults[:1]
    assert transitions(faults, 1.0, 1.1) == []


def test_faults_reach_every_method_and_are_logged(tmp_path) -> None:
    scenario = build_scenario(load_scenario_file(conf_dir() / "scenario" / "corridor.yaml"))
    world = WorldConfig(faults=[Fault(kind="stuck", robot=3, start=2.0, end=4.0)])
    log = tmp_path / "e.mcap"
    run_episode(
        scenario, Geometry.of(scenario), make_controller(StraightConfig()), "straight", 0, world, SensingConfig(),
        log_path=log,
    )  # fmt: skip
    rec = read_episode(log)
    events = [(round(e["time"], 1), e["kind"], e["robots"]) for e in rec.events]
    assert (2.0, "fault", [3]) in events and (4.0, "fault_end", [3]) in events
    at = {round(float(t), 1): k for k, t in enumerate(rec.time)}
    moved = np.linalg.norm(np.diff(rec.positions[:, 3], axis=0), axis=1)
    assert moved[at[2.6] : at[4.0]].max() < 1e-6 < moved[at[4.5] : at[5.0]].min()  # held, then free again
