"""`stafpipe eval`: N seeded episodes of a method on a scenario.

Writes `results.parquet/.csv` (one row per episode), `summary.parquet/.csv` (mean and 95 % confidence interval of every
metric, Student t), and `episodes/episode_NNNN.mcap` (one log per episode).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf
from scipy import stats

from stafpipe.config.checks import SEED_STRIDE
from stafpipe.config.schema import EvalConfig
from stafpipe.controllers import make_controller
from stafpipe.episode import run_episodes
from stafpipe.errors import require
from stafpipe.geometry import Geometry
from stafpipe.io import write_table
from stafpipe.progress import progress
from stafpipe.scenario import Scenario, resolve_scenario
from stafpipe.scenario_pool import with_overrides
from stafpipe.sections import section
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig

log = logging.getLogger(__name__)
AUTO_BATCH = 50
"""`eval.batch=0`: episodes run at once. Measured on 2 cores, 50 corridor episodes: the speed-up levels off from 10-25
worlds (DGNN 16.3 s one at a time, 4.5 s at 10, 3.9 s at 25 and 50) and 50 is no slower than those."""
PAIRS_PER_BATCH = 5_000_000
"""`eval.batch=0` caps the batch at this many robot pairs (B x n^2): observations hold (B, n, n, ...) arrays. Measured
(tracemalloc, one world step of 1,000 robots): 40 MiB at one world, 202 MiB at 5, so 50 worlds would need
about 2 GB; the cap gives 5."""


def auto_batch(n: int) -> int:
    """The batch `eval.batch=0` runs for teams of n robots."""
    return max(1, min(AUTO_BATCH, PAIRS_PER_BATCH // (n * n)))


def episode_seed(seed: int, k: int) -> int:
    """Seed of episode k of a run seeded `seed`."""
    return seed * SEED_STRIDE + k


def scenario_for(cfg: DictConfig) -> Scenario:
    """The run's scenario, with the `formation` and `robot` groups' non-null fields replacing the scenario's own.

    The result is built (and so validated) again, so an override such as `robot.drive=tank` fails like a bad file would.
    """
    return with_overrides(resolve_scenario(cfg.scenario), cfg)


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """Mean and 95 % confidence half-width (Student t) of every numeric metric, NaNs (e.g. TT of failed runs) left
    out."""
    rows = []
    for col in df.columns:
        if col in ("episode", "seed") or not pd.api.types.is_numeric_dtype(df[col]):
            continue
        x = df[col].to_numpy(float)
        x = x[np.isfinite(x)]
        half = float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))) if len(x) > 1 else math.nan
        rows.append({"metric": col, "mean": float(x.mean()) if len(x) else math.nan, "ci95": half, "n": len(x)})
    return pd.DataFrame(rows)


def run_eval(cfg: DictConfig, out_dir: Path) -> list[Path]:
    """Evaluate `cfg.method` on `cfg.scenario`."""
    ev = section(cfg.eval, EvalConfig)
    ev.check()
    scenario = scenario_for(cfg)
    world_cfg = section(cfg.world, WorldConfig)
    limit = scenario.spec.time_limit
    for k, fault in enumerate(world_cfg.faults):
        require(
            fault.start < limit,
            f"world.faults[{k}].start",
            f"must be before the scenario's time limit ({limit:g} s): the fault would never fire",
            fault.start,
        )
    sensing = section(cfg.sensing, SensingConfig)
    method_cfg: Any = OmegaConf.to_object(cfg.method)
    geometry = Geometry.of(scenario)
    controller = make_controller(method_cfg)  # once: a learned method loads its checkpoints here
    size = ev.batch or auto_batch(scenario.spec.team.n)
    rows, outputs = [], []
    batches = [list(range(first, min(first + size, ev.episodes))) for first in range(0, ev.episodes, size)]
    desc = f"eval {method_cfg.name} on {scenario.name} ({ev.episodes} episodes in batches of <= {size})"
    for ks in progress(batches, desc=desc, unit="episode", total=ev.episodes, size=len):
        seeds = [episode_seed(int(cfg.seed), k) for k in ks]
        logs = [out_dir / "episodes" / f"episode_{k:04d}.mcap" if ev.log_episodes else None for k in ks]
        results = run_episodes(
            scenario, geometry, controller, method_cfg.name, seeds, world_cfg, sensing, ev.goal_tolerance,
            ev.cfi_margin, logs,
        )  # fmt: skip
        for w, (k, seed, values) in enumerate(zip(ks, seeds, results, strict=True)):
            rows.append(
                {
                    "episode": k,
                    "seed": seed,
                    "method": method_cfg.name,
                    "label": ev.label,
                    "scenario": scenario.name,
                    "formation": scenario.spec.team.formation,
                    "n": scenario.spec.team.n,
                    "drive": scenario.spec.robot.drive,
                    **values,
                    **controller.world_view(w).episode_stats(),
                }
            )
        outputs += [p for p in logs if p]
    df = pd.DataFrame(rows)
    summary = summarise(df)
    outputs += write_table(df, out_dir / "results") + write_table(summary, out_dir / "summary")
    shown = summary[summary.metric.isin(["sr", "tt", "tt_ratio", "cfi_0.5", "cfi_0.1", "cfi_0.01", "collisions"])]
    log.info("%s on %s (%d episodes):\n%s", method_cfg.name, scenario.name, ev.episodes, shown.to_string(index=False))
    return outputs
