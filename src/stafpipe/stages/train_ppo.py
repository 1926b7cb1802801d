"""`stafpipe train-ppo`: train a navigation policy (method=dgnn) with PPO on batched worlds of the harness.

Writes `policy.pt` (the checkpoint `method=dgnn method.checkpoint=...` loads), `ppo_state.pt` (the full training state,
every `train_ppo.checkpoint_every` iterations), `learning_curves.parquet/.csv` (rewritten every iteration) and
`learning_curves.png/.pdf`. `train_ppo.resume=true` continues from the newest state of the same config.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
from pathlib import Path

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from stafpipe.errors import StafpipeError
from stafpipe.io import save_figure, write_table
from stafpipe.learning.config import TrainPPOConfig
from stafpipe.paths import conf_dir
from stafpipe.scenario import Scenario, build_scenario, load_scenario_file

log = logging.getLogger(__name__)


def load_named_scenario(name: str) -> Scenario:
    """A built-in scenario by name (conf/scenario/<name>.yaml) or a scenario file by path."""
    builtin = conf_dir() / "scenario" / f"{name}.yaml"
    return build_scenario(load_scenario_file(builtin if builtin.is_file() else Path(name)))


def resume_state(out_dir: Path, digest: str) -> Path | None:
    """The newest training state of this config: in this run directory, else anywhere under outputs/train-ppo/."""
    import torch

    from stafpipe.learning.ppo import STATE_FILE

    candidates = [out_dir / STATE_FILE]
    candidates += sorted(Path("outputs").rglob(STATE_FILE), key=lambda p: p.stat().st_mtime, reverse=True)
    for path in candidates:
        if path.is_file() and torch.load(path, map_location="cpu", weights_only=True).get("config_hash") == digest:
            return path
    return None


def _path_and_width(scenario: Scenario, method: str) -> tuple[np.ndarray, float]:
    """The team centre's shortest path (for staf: through the middle of the passages, as `method=staf` plans) and the
    narrowest passage on the way (as an eval episode computes them)."""
    from stafpipe.episode import centred_path, episode_context
    from stafpipe.geometry import Geometry
    from stafpipe.sensing import SensingConfig

    geometry = Geometry(scenario)
    ctx, path = episode_context(scenario, geometry, SensingConfig(), 0.3, 0.0)
    return (centred_path(scenario, geometry, ctx.passage_width) if method == "staf" else path), ctx.passage_width


def run_train_ppo(cfg: DictConfig, out_dir: Path) -> list[Path]:
    from stafpipe.launch import config_hash
    from stafpipe.learning.checkpoint import save_policy
    from stafpipe.learning.ppo import STATE_FILE, train_ppo
    from stafpipe.plots.training import ppo_figure
    from stafpipe.sensing import SensingConfig
    from stafpipe.stages.eval import with_overrides
    from stafpipe.training_record import commit
    from stafpipe.world import WorldConfig

    tc: TrainPPOConfig = OmegaConf.to_object(cfg.train_ppo)  # type: ignore[assignment]
    tc.check()
    world_cfg: WorldConfig = OmegaConf.to_object(cfg.world)  # type: ignore[assignment]
    sensing: SensingConfig = OmegaConf.to_object(cfg.sensing)  # type: ignore[assignment]
    pool = [with_overrides(load_named_scenario(name), cfg) for name in tc.scenarios]
    if tc.formations:  # every scenario with every formation of the curriculum
        pool = [build_scenario(dataclasses.replace(s.spec, team=dataclasses.replace(s.spec.team, formation=kind)))
                for s in pool for kind in tc.formations]
    if tc.team_sizes:
        pool = [build_scenario(dataclasses.replace(s.spec, team=dataclasses.replace(s.spec.team, n=n)))
                for s in pool for n in tc.team_sizes]
    if any(s.spec.robot != pool[0].spec.robot for s in pool):
        raise StafpipeError("train_ppo.scenarios: all need the same robot (set the `robot` group to make them equal)")
    drawn = [(s, *_path_and_width(s, tc.method)) for s in pool]
    sizes = sorted({s.spec.team.n for s in pool})

    def draw(rng: np.random.Generator, count: int) -> list[tuple[Scenario, np.ndarray, float]]:
        # one team size per iteration (a batch of worlds shares n); scenarios of that size drawn uniformly
        n = sizes[int(rng.integers(len(sizes)))] if len(sizes) > 1 else sizes[0]
        same = [d for d in drawn if d[0].spec.team.n == n]
        return [same[int(k)] for k in rng.integers(len(same), size=count)]

    plain = copy.deepcopy(cfg)
    plain.train_ppo.resume = False  # the same run, resumed or not, has one hash
    digest = config_hash(plain)
    resume_from = resume_state(out_dir, digest) if tc.resume else None
    if tc.resume and resume_from is None:
        log.warning("train_ppo.resume: no saved state of this config; starting afresh")
    curves = out_dir / "learning_curves"

    def on_iteration(history: list[dict[str, float]]) -> None:
        write_table(pd.DataFrame(history), curves)

    policy, history = train_ppo(tc, draw, world_cfg, sensing, float(cfg.eval.goal_tolerance), int(cfg.seed), out_dir,
                                digest, resume_from, on_iteration)
    made_by = {"train_ppo": OmegaConf.to_container(cfg.train_ppo, resolve=True), "seed": int(cfg.seed),
               "commit": commit(), "iterations": len(history), "final": history[-1] if history else {}}
    outputs = [save_policy(out_dir / "policy.pt", tc.method, policy, made_by), out_dir / STATE_FILE]
    outputs += write_table(pd.DataFrame(history), curves)
    outputs += save_figure(ppo_figure(history), curves, dpi=120)
    last = history[-1]
    log.info("iteration %d: success rate %.3f, return %.2f", last["iteration"], last["charts/success_rate"],
             last["charts/episode_return"])
    return outputs
