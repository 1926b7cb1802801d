"""`stafpipe train-ppo`: train a navigation policy (method=dgnn) with PPO on batched worlds of the harness.

Writes `policy.pt` (the checkpoint `method=dgnn method.checkpoint=...` loads), `ppo_state.pt` (the full training state,
every `train_ppo.checkpoint_every` iterations), `learning_curves.parquet/.csv` (rewritten every iteration) and
`learning_curves.png/.pdf`. `train_ppo.resume=true` continues from the newest state of the same config.
"""

from __future__ import annotations

import copy
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf
from torch.distributed.elastic.multiprocessing.errors import record

from stafpipe.errors import StafpipeError
from stafpipe.io import OBJECTIVE, save_figure, write_json, write_table
from stafpipe.learning.config import TrainPPOConfig
from stafpipe.learning.distributed import ALONE, Workers, joined, launch, leave
from stafpipe.progress import progress
from stafpipe.scenario import Scenario
from stafpipe.scenario_pool import curriculum, path_and_width, scenario_pool
from stafpipe.sections import section

if TYPE_CHECKING:
    from stafpipe.learning.policy_net import PolicyNet
    from stafpipe.learning.ppo import Drawn

log = logging.getLogger(__name__)
LOG_FORMAT = "[%(asctime)s][%(name)s][%(levelname)s] - %(message)s"
"""The workers' log lines, as Hydra writes the run's."""


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


BUILT_IN_TEST_MAPS = {
    *("corridor", "bridge", "doorway", "narrowing", "multi_passage", "bollards", "forest"),
    *("corridor_walker", "crossing_walkers"),
}
"""STAF's maps (conf/scenario/): what learned methods are tested on, never trained on (docs/decisions.md)."""


def by_team(drawn: list[Drawn]) -> dict[str, list[Drawn]]:
    """Worlds grouped by team size and robot: the worlds of one batch must share both."""
    groups: dict[str, list[Drawn]] = {}
    for d in drawn:
        groups.setdefault(f"{d[0].spec.team.n}|{d[0].spec.robot}", []).append(d)
    return groups


def validation_batches(tc: TrainPPOConfig, cfg: DictConfig, training: set[str]) -> list[list[Drawn]]:
    """`tc.validation_episodes` held-out worlds, spread over the validation scenarios in turn (judged on the
    formations it is trained for), grouped into batches that share a team size and robot; refused where a validation
    scenario is also a training one."""
    pool = scenario_pool(tc.validation, cfg, tc.formations, "train_ppo.validation")
    shared = sorted({s.name for s in pool} & training)
    if shared:
        raise StafpipeError(f"train_ppo.validation: {shared} are also training scenarios; validation must be held out")
    worlds = [pool[k % len(pool)] for k in range(tc.validation_episodes)] if pool else []
    groups = by_team([(s, *path_and_width(s)) for s in worlds])
    return [groups[k] for k in sorted(groups)]


def kept_score(history: list[dict[str, float]]) -> dict[str, object]:
    """What a search maximises (`objective.json`): the validation success rate of the iteration whose weights
    `policy.pt` holds (`best_validation`; the warm start's as iteration 0), or, without validation scenarios, the
    last iteration's training success rate (a run trains at least one iteration). Each names itself."""
    from stafpipe.learning.ppo import best_validation

    top = best_validation(history)
    if top is None:
        value, name = history[-1]["charts/success_rate"], "charts/success_rate of the last iteration"
    else:
        value, name = top["val/success_rate"], f"val/success_rate of iteration {int(top['iteration'])} (kept)"
    return {"name": name, "value": float(value), "direction": "maximize"}


def _training_pool(cfg: DictConfig, tc: TrainPPOConfig) -> list[Scenario]:
    """The scenarios training draws from (`train_ppo.scenarios`, team sizes applied)."""
    pool = scenario_pool(tc.scenarios, cfg, tc.formations, "train_ppo.scenarios")
    return curriculum(pool, "n", tc.team_sizes, "train_ppo.scenarios") if tc.team_sizes else pool


def _train(
    cfg: DictConfig, out_dir: Path, digest: str, resume_from: Path | None, workers: Workers, pool: list[Scenario]
) -> tuple[PolicyNet, list[dict[str, float]], list[str]]:
    """Train in this process as one of `workers` on the training scenarios `pool`: (network, history, validation
    map names). The main worker writes the learning curves and TensorBoard events every iteration."""
    from stafpipe.learning.ppo import train_ppo
    from stafpipe.sensing import SensingConfig
    from stafpipe.tensorboard_log import ScalarLog
    from stafpipe.world import WorldConfig

    tc = section(cfg.train_ppo, TrainPPOConfig)
    world_cfg = section(cfg.world, WorldConfig)
    sensing = section(cfg.sensing, SensingConfig)
    drawn = [(s, *path_and_width(s)) for s in progress(pool, desc="train-ppo: maps", unit="map")]
    groups = by_team(drawn)  # one group per iteration
    keys = sorted(groups)

    validation = validation_batches(tc, cfg, {s.name for s in pool})

    def draw(rng: np.random.Generator, count: int) -> list[tuple[Scenario, np.ndarray, float]]:
        # one group per iteration; its scenarios drawn uniformly
        same = groups[keys[int(rng.integers(len(keys)))] if len(keys) > 1 else keys[0]]
        return [same[int(k)] for k in rng.integers(len(same), size=count)]

    curves = out_dir / "learning_curves"
    board = ScalarLog(out_dir, "iteration") if workers.main else None

    def on_iteration(history: list[dict[str, float]]) -> None:
        write_table(pd.DataFrame(history), curves)
        if board is not None:
            board.sync(history)

    try:
        policy, history = train_ppo(
            tc,
            draw,
            world_cfg,
            sensing,
            float(cfg.eval.goal_tolerance),
            int(cfg.seed),
            out_dir,
            digest,
            resume_from,
            on_iteration,
            validation,
            workers,
        )
        if board is not None:
            board.sync(history)  # a resumed run with no iteration left to train writes the history it took over
    finally:
        if board is not None:
            board.close()
    return policy, history, sorted({d[0].name for batch in validation for d in batch})


@record  # a failure's message reaches the launching process (distributed.launch)
def _worker(
    resolved: DictConfig, out_dir: str, digest: str, resume_from: str | None
) -> tuple[dict, list[dict[str, float]], list[str]] | None:
    """One process of `train_ppo.workers` (started by `distributed.launch`): joins the others, trains its share,
    and (the main worker) returns the weights, the history and the validation maps. The main worker logs to the
    console and to the run's log file, the others their errors only."""
    logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
    workers = joined()
    try:
        if workers.main and (Path(out_dir) / "train-ppo.log").is_file():
            to_file = logging.FileHandler(Path(out_dir) / "train-ppo.log")
            to_file.setFormatter(logging.Formatter(LOG_FORMAT))
            logging.getLogger().addHandler(to_file)
        if not workers.main:
            logging.getLogger("stafpipe").setLevel(logging.ERROR)
        resume = None if resume_from is None else Path(resume_from)
        pool = _training_pool(resolved, section(resolved.train_ppo, TrainPPOConfig))
        policy, history, validation_maps = _train(resolved, Path(out_dir), digest, resume, workers, pool)
        return (policy.state_dict(), history, validation_maps) if workers.main else None
    finally:
        leave()


def run_train_ppo(cfg: DictConfig, out_dir: Path) -> list[Path]:
    from stafpipe.launch import config_hash
    from stafpipe.learning.checkpoint import build_policy, save_policy
    from stafpipe.learning.ppo import STATE_FILE, best_iteration
    from stafpipe.plots.training import ppo_figure
    from stafpipe.tensorboard_log import TB_DIR
    from stafpipe.training_record import commit

    tc = section(cfg.train_ppo, TrainPPOConfig)
    tc.check()
    plain = copy.deepcopy(cfg)
    plain.train_ppo.resume = False  # the same run, resumed or not, has one hash
    digest = config_hash(plain)
    resume_from = resume_state(out_dir, digest) if tc.resume else None
    if tc.resume and resume_from is None:
        log.warning("train_ppo.resume: no saved state of this config; starting afresh")
    pool = _training_pool(cfg, tc)
    test_maps = sorted({s.name for s in pool} & BUILT_IN_TEST_MAPS)
    if test_maps:
        log.warning(
            "train_ppo.scenarios include the built-in test maps %s: results on them are not held out", test_maps
        )
    if tc.workers == 1:
        policy, history, validation_maps = _train(cfg, out_dir, digest, resume_from, ALONE, pool)
    else:
        resolved = copy.deepcopy(cfg)
        OmegaConf.resolve(resolved)  # the workers have no Hydra to resolve with; the typed sections travel pickled
        where = None if resume_from is None else str(resume_from)
        weights, history, validation_maps = launch(tc.workers, _worker, resolved, str(out_dir), digest, where)
        policy = build_policy(tc.method, tc.policy)
        policy.load_state_dict(weights)
    curves = out_dir / "learning_curves"
    made_by = {
        "train_ppo": OmegaConf.to_container(cfg.train_ppo, resolve=True),
        "seed": int(cfg.seed),
        "sensing": OmegaConf.to_container(cfg.sensing, resolve=True),
        "world": OmegaConf.to_container(cfg.world, resolve=True),
        "training_maps": sorted({s.name for s in pool}),
        # the top speed the actions are fractions of: faster robots are driven no faster (controllers/learned.py)
        "max_speed": max(float(s.spec.robot.max_speed) for s in pool),
        "commit": commit(),
        "iterations": len(history),
        "final": history[-1] if history else {},
        "validation_maps": validation_maps,
        "selected_iteration": len(history) if (chosen := best_iteration(history)) is None else chosen,
    }
    outputs = [save_policy(out_dir / "policy.pt", tc.method, policy, made_by), out_dir / STATE_FILE]
    outputs.append(write_json(out_dir / OBJECTIVE, kept_score(history)))
    outputs += sorted((out_dir / TB_DIR).iterdir())
    outputs += write_table(pd.DataFrame(history), curves)
    outputs += save_figure(ppo_figure(history), curves, dpi=120)
    last = history[-1]
    log.info(
        "iteration %d: success rate %.3f, return %.2f",
        last["iteration"],
        last["charts/success_rate"],
        last["charts/episode_return"],
    )
    return outputs
