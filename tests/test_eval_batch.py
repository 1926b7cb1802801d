"""Batched evaluation: every method runs the episodes of one eval in parallel worlds, and an episode's result does not
depend on the batch it ran in."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pandas as pd
import pytest

from stafpipe.controllers import make_controller, method_config_class
from stafpipe.episode import run_episodes
from stafpipe.geometry import Geometry
from stafpipe.launch import launch
from stafpipe.scenario import TeamSpec, build_scenario
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.stages.eval import auto_batch
from stafpipe.world import WorldConfig

SEEDS = [11, 12, 13]


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    return a.keys() == b.keys() and all(a[k] == b[k] or (math.isnan(a[k]) and math.isnan(b[k])) for k in a)


def _both_ways(method: str, scenario, world: WorldConfig, tmp_path: Path) -> tuple[list[dict], list[dict]]:
    """The episodes of SEEDS in one batch, and each alone; MCAP logs under tmp_path/batch and tmp_path/alone."""
    geometry, sensing = Geometry.of(scenario), SensingConfig()
    controller = make_controller(method_config_class(method)())
    logs: list[Path | None] = [tmp_path / "batch" / f"{s}.mcap" for s in SEEDS]
    alone_dir = tmp_path / "alone"
    batched = run_episodes(scenario, geometry, controller, method, SEEDS, world, sensing, log_paths=logs)
    alone = [
        run_episodes(scenario, geometry, controller, method, [s], world, sensing, log_paths=[alone_dir / f"{s}.mcap"])[
            0
        ]
        for s in SEEDS
    ]
    return batched, alone


SLOW = pytest.mark.slow  # 1-2 s each; together they would push `-m "not slow"` past 90 s


@pytest.mark.parametrize(
    "method",
    ["straight", "cezayirli", pytest.param("lf", marks=SLOW), pytest.param("zhu", marks=SLOW)]
    + [pytest.param("dgnn", marks=SLOW), pytest.param("staf_planned", marks=SLOW)],
)
def test_a_batch_gives_each_episode_exactly_as_alone(method, tmp_path) -> None:
    corridor = load_named_scenario("corridor")
    scenario = build_scenario(dataclasses.replace(corridor.spec, time_limit=6.0))
    batched, alone = _both_ways(method, scenario, WorldConfig(start_noise=0.2), tmp_path)
    assert all(_same(a, b) for a, b in zip(batched, alone, strict=True))
    assert len({r["cfi_0.5"] for r in alone}) == len(SEEDS)  # the episodes differ, so a mix-up would show
    for s in SEEDS:  # the logs too, byte for byte
        assert (tmp_path / "batch" / f"{s}.mcap").read_bytes() == (tmp_path / "alone" / f"{s}.mcap").read_bytes()


def test_a_world_that_finishes_early_is_left_alone(tmp_path) -> None:
    """Episodes that end at different steps: the finished world stops being recorded while the others go on."""
    spec = load_named_scenario("corridor").spec
    open_lane = dataclasses.replace(
        spec,
        obstacles=[],
        team=TeamSpec(n=4, formation="square", spacing=1.5, start=(3.0, 6.0), goal=(8.0, 6.0), heading_deg=0.0),
        reference_path=[],
        time_limit=20.0,
    )
    scenario = build_scenario(open_lane)  # 1.5 m apart: straight-line robots starting 0.4 m off their slots never meet
    batched, alone = _both_ways("straight", scenario, WorldConfig(start_noise=0.4), tmp_path)
    assert all(_same(a, b) for a, b in zip(batched, alone, strict=True))
    assert len({r["tt"] for r in alone}) > 1 and all(r["sr"] == 1.0 for r in alone)


@SLOW
def test_eval_batch_size_changes_nothing_but_the_time(workdir) -> None:
    common = ["method=lf", "scenario=corridor", "scenario.time_limit=5", "eval.episodes=3", "world.start_noise=0.2"]
    assert launch("eval", [*common, "eval.batch=1"]) == 0
    assert launch("eval", [*common, "eval.batch=2"]) == 0
    runs = sorted(p.parent for p in workdir.glob("outputs/eval/*/*/stage.json"))
    one, two = (pd.read_parquet(r / "results.parquet") for r in runs)
    pd.testing.assert_frame_equal(one, two)


def test_the_automatic_batch_keeps_large_teams_small() -> None:
    """Observations hold (B, n, n) arrays: 50 worlds of ten robots, but only 5 of 1,000 and one of 3,000."""
    assert (auto_batch(10), auto_batch(316), auto_batch(1000), auto_batch(3000)) == (50, 50, 5, 1)
