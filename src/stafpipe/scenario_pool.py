"""The scenarios a run works on: built-in ones by name, files and directories of them, the run's `formation` and
`robot` overrides, training pools with a formation curriculum, and each scenario's path and narrowest passage as an
episode computes them. Shared by the stages (eval, train-ppo) and the library (the PettingZoo environment), so it
imports no stage."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from stafpipe.config.schema import FormationConfig, RobotConfig
from stafpipe.errors import StafpipeError
from stafpipe.paths import conf_dir
from stafpipe.scenario import Scenario, build_scenario, load_scenario_file
from stafpipe.sections import section

log = logging.getLogger(__name__)


def load_named_scenario(name: str) -> Scenario:
    """A built-in scenario by name (conf/scenario/<name>.yaml) or a scenario file by path."""
    builtin = conf_dir() / "scenario" / f"{name}.yaml"
    return build_scenario(load_scenario_file(builtin if builtin.is_file() else Path(name)))


def with_overrides(scenario: Scenario, cfg: DictConfig) -> Scenario:
    """`scenario` with the `formation` and `robot` groups' non-null fields in place of its own."""
    formation = section(cfg.formation, FormationConfig)
    formation.check(allow_unset=True)
    robot = section(cfg.robot, RobotConfig)
    spec = scenario.spec
    if formation.type is not None:
        spacing = formation.spacing if formation.spacing is not None else spec.team.spacing
        spec = dataclasses.replace(
            spec,
            team=dataclasses.replace(
                spec.team, formation=formation.type, angle_deg=formation.angle_deg, spacing=spacing
            ),
        )
    if robot.overrides():
        spec = dataclasses.replace(spec, robot=dataclasses.replace(spec.robot, **robot.overrides()))
    return scenario if spec is scenario.spec else build_scenario(spec)


def path_and_width(scenario: Scenario) -> tuple[np.ndarray, float]:
    """The team centre's shortest path (TeamInfo.path) and the narrowest passage on the way, as an eval episode
    computes them."""
    from stafpipe.episode import episode_context
    from stafpipe.geometry import Geometry
    from stafpipe.sensing import SensingConfig

    ctx, path = episode_context(scenario, Geometry.of(scenario), SensingConfig(), 0.3, 0.0)
    return path, ctx.passage_width


def scenario_files(entry: str) -> list[str]:
    """A `train_ppo.scenarios` entry as scenario names or files: a directory stands for every `*.yaml` in it."""
    path = Path(entry)
    if path.is_dir():
        files = sorted(str(p) for p in path.glob("*.yaml"))
        if not files:
            raise StafpipeError(f"train_ppo.scenarios: directory {entry} holds no scenario *.yaml file")
        return files
    return [entry]


def curriculum(pool: list[Scenario], field: str, values: list, key: str) -> list[Scenario]:
    """Every scenario of `pool` with each of `values` as its team's `field` (formation or n); a variant whose team
    does not fit its map (a line of 11 wider than the map's goal area) is left out with a warning, not trained on."""
    from stafpipe.scenario import ScenarioError

    out, left_out = [], []
    for s in pool:
        for value in values:
            try:
                out.append(
                    build_scenario(dataclasses.replace(s.spec, team=dataclasses.replace(s.spec.team, **{field: value})))
                )
            except ScenarioError as exc:
                left_out.append(f"{s.name} with {field} {value} ({exc})")
    if left_out:
        shown = "; ".join(left_out[:3]) + (" ..." if len(left_out) > 3 else "")
        total = len(pool) * len(values)
        log.warning("%s: %d of %d variants left out, their team does not fit: %s", key, len(left_out), total, shown)
    if left_out and not out:
        raise StafpipeError(f"{key}: no scenario fits its team with these {field}s {values}: {left_out[0]}")
    return out


def scenario_pool(entries: list[str], cfg: DictConfig, formations: list[str], key: str) -> list[Scenario]:
    """The scenarios of `entries` (names, files, directories) with the run's overrides, each with every curriculum
    formation (none: its own)."""
    pool = [with_overrides(load_named_scenario(name), cfg) for entry in entries for name in scenario_files(entry)]
    return curriculum(pool, "formation", formations, key) if formations and pool else pool
