"""What the report reads: the finished run directories of eval and ablate stages, gathered into frames.

A run is identified by what it ran (its results' method, scenario, formation, team size, drive and label, and from its
resolved config the injected faults and the sensing's occlusion), never by its directory's name, so the report works as
well on a sweep's job directories or a user's own runs as on `stafpipe run reproduce`'s steps.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf
from scipy import stats

from stafpipe.errors import StafpipeError
from stafpipe.launch import MARKER
from stafpipe.plots.staf_tables import mean_ci
from stafpipe.report.verdicts import Number


def _faults(world: Any) -> str:
    """The run's injected faults as one comparable string ("" when none)."""
    faults = OmegaConf.to_container(world.get("faults", [])) if world is not None else []
    return json.dumps(faults, sort_keys=True) if faults else ""


@dataclass
class Evidence:
    """Every episode row of the eval runs, and the per-team rows of the ablate studies (by study name)."""

    episodes: pd.DataFrame
    ablations: dict[str, pd.DataFrame] = field(default_factory=dict)
    figures: list[Path] = field(default_factory=list)
    """The PNG figures of the plot runs among the run directories."""

    def select(self, **where: Any) -> pd.DataFrame:
        """The episode rows whose columns equal every given value (label, faults default to "": the plain runs)."""
        where = {"label": "", "faults": "", **where}
        rows = self.episodes
        for key, value in where.items():
            if key not in rows.columns:
                return rows.iloc[0:0]
            rows = rows[rows[key] == value]
        return rows

    def number(self, column: str, scale: float = 1.0, unit: str = "", **where: Any) -> Number:
        """Mean and 95 % CI of `column` over the selected episodes (NaN when none)."""
        return column_number(self.select(**where), column, scale, unit)

    def study(self, name: str) -> pd.DataFrame:
        return self.ablations.get(name, pd.DataFrame())


RATES = frozenset({"sr", "sub1_sr", "sub2_sr", "made"})
"""Columns that are rates in [0, 1] per episode: their interval is Wilson's (`wilson`), not a mean's."""
Z95 = float(stats.norm.ppf(0.975))


def column_number(rows: pd.DataFrame, column: str, scale: float = 1.0, unit: str = "") -> Number:
    """Mean of `column` over `rows` with its 95 % interval, times `scale` (NaN when there is none): Wilson's for a
    rate (`RATES`), else the wider of Student's t and a BCa bootstrap (`mean_interval`)."""
    if rows.empty or column not in rows:
        return Number(math.nan)
    values = rows[column].dropna().to_numpy(float)
    if len(values) == 0:
        return Number(math.nan)
    mean = float(values.mean())
    if column in RATES:
        low, high = wilson(mean, len(values))
        return Number(mean * scale, math.nan, len(values), unit, low * scale, high * scale)
    return Number(mean * scale, mean_interval(values) * scale, len(values), unit)


def wilson(rate: float, n: int) -> tuple[float, float]:
    """Wilson's 95 % score interval (Wilson, JASA 1927) for a rate observed over n episodes. An episode's success
    rate is the fraction of its robots that arrived, a number in [0, 1] whose variance is at most rate x (1 - rate):
    the interval of n Bernoulli trials is at least as wide as that mean's, so it never flatters."""
    z2n = Z95**2 / n
    centre = (rate + z2n / 2) / (1 + z2n)
    half = Z95 / (1 + z2n) * math.sqrt(max(rate * (1 - rate), 0.0) / n + z2n / (4 * n))
    return max(centre - half, 0.0), min(centre + half, 1.0)


def mean_interval(values: np.ndarray) -> float:
    """The 95 % half-width of a mean: the wider of Student's t and a BCa bootstrap (scipy.stats.bootstrap, 2,000
    resamples, a fixed seed: the report is reproducible); NaN for one value, 0 when every value is the same."""
    if len(values) < 2:
        return math.nan
    if np.ptp(values) == 0:
        return 0.0
    _, t_half = mean_ci(pd.Series(values))
    boot = stats.bootstrap((values,), np.mean, n_resamples=2000, method="BCa", rng=np.random.default_rng(0))
    low, high = boot.confidence_interval
    mean = float(values.mean())
    spread = max(mean - low, high - mean)
    return max(t_half, float(spread)) if math.isfinite(spread) else t_half


def lowest(numbers: list[Number]) -> Number:
    """The measured number with the lowest interval's lower end (the weakest for an at-least claim; NaN when none
    was measured)."""
    found = [x for x in numbers if not math.isnan(x.value)]
    return min(found, key=lambda x: (x.lower, x.value)) if found else Number(math.nan)


def episode_records(rows: pd.DataFrame) -> list[Any]:
    """The logged episodes (episode_log.EpisodeRecord) behind episode rows, read from their runs' MCAP files."""
    from stafpipe.episode_log import read_episode

    if rows.empty:
        return []
    return [
        read_episode(Path(str(d)) / "episodes" / f"episode_{int(e):04d}.mcap")
        for d, e in zip(rows["run_dir"].tolist(), rows["episode"].tolist(), strict=True)
    ]


def _read_table(run_dir: Path, stem: str) -> pd.DataFrame:
    csv = run_dir / f"{stem}.csv"
    if not csv.is_file():
        raise StafpipeError(f"plot.run_dirs: {run_dir} is a finished run without {stem}.csv")
    try:
        return pd.read_csv(csv, keep_default_na=False, na_values=[""])
    except (OSError, ValueError) as exc:
        raise StafpipeError(f"plot.run_dirs: {csv}: not a readable table ({exc})") from None


def gather(run_dirs: list[Path]) -> Evidence:
    """Read every finished eval and ablate run among `run_dirs` (other stages are skipped; an unfinished or damaged
    run is an error naming it)."""
    episodes: list[pd.DataFrame] = []
    ablations: dict[str, pd.DataFrame] = {}
    figures: list[Path] = []
    for run_dir in run_dirs:
        if not (run_dir / MARKER).is_file():
            raise StafpipeError(f"plot.run_dirs: {run_dir} is not a finished run (no {MARKER})")
        try:
            cfg = OmegaConf.load(run_dir / "config.yaml")
        except Exception as exc:  # noqa: BLE001 - any parse error is one message naming the file
            raise StafpipeError(f"plot.run_dirs: {run_dir / 'config.yaml'}: not readable ({exc})") from None
        if not isinstance(cfg, DictConfig):
            raise StafpipeError(f"plot.run_dirs: {run_dir / 'config.yaml'}: not a mapping")
        stage = cfg.get("stage")
        if stage == "eval":
            rows = _read_table(run_dir, "results")
            rows["label"] = rows["label"].astype(object).fillna("").astype(str) if "label" in rows else ""
            rows["faults"] = _faults(cfg.get("world"))
            rows["occlusion"] = bool(cfg.sensing.get("occlusion", False)) if "sensing" in cfg else False
            rows["run_dir"] = str(run_dir)
            episodes.append(rows)
        elif stage == "ablate":
            study = str(cfg.ablate.study)
            ablations[study] = pd.concat([ablations.get(study, pd.DataFrame()), _read_table(run_dir, "results")])
        if stage in ("plot", "ablate"):
            figures += sorted(run_dir.glob("*.png"))
    frame = pd.concat(episodes, ignore_index=True) if episodes else pd.DataFrame()
    return Evidence(frame, ablations, figures)
