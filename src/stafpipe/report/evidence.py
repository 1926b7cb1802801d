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

import pandas as pd
from omegaconf import DictConfig, OmegaConf

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


def column_number(rows: pd.DataFrame, column: str, scale: float = 1.0, unit: str = "") -> Number:
    """Mean and 95 % CI of `column` over `rows`, times `scale` (NaN when there is none)."""
    if rows.empty or column not in rows:
        return Number(math.nan)
    mean, ci = mean_ci(rows[column])
    return Number(mean * scale, ci * scale, int(rows[column].notna().sum()), unit)


def lowest(numbers: list[Number]) -> Number:
    """The lowest of the measured numbers (NaN when none was measured)."""
    found = [x for x in numbers if not math.isnan(x.value)]
    return min(found, key=lambda x: x.value) if found else Number(math.nan)


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
