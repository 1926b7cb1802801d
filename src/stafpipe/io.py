"""Atomic output writing: a reader never sees a half-written file, a killed run leaves none behind."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

if TYPE_CHECKING:
    from matplotlib.figure import Figure


OBJECTIVE = "objective.json"
"""A run's one number to optimise, where its stage has one (train-ppo: the validation success rate of the weights it
kept): `{"name", "value", "direction"}`. Hydra's task function returns its value (`launch.objective`), which is what
a sweeper that searches (Optuna's) reads of each job."""


def atomic_write(path: Path, write: Callable[[Path], object]) -> Path:
    """Call `write(tmp)` on a temporary sibling of `path`, then rename it into place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def write_json(path: Path, data: Any) -> Path:
    """Write `data` as indented JSON, atomically."""
    return atomic_write(path, lambda tmp: tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n"))


def write_table(df: pd.DataFrame, stem: Path, metadata: dict[str, str] | None = None) -> list[Path]:
    """Write `df` as `stem.parquet` (with key/value metadata) and its CSV twin `stem.csv`, each atomically."""
    table = pa.Table.from_pandas(df, preserve_index=False)
    if metadata:
        merged = dict(table.schema.metadata or {})
        merged.update({k.encode(): v.encode() for k, v in metadata.items()})
        table = table.replace_schema_metadata(merged)
    stem = Path(stem)
    parquet = atomic_write(stem.with_suffix(".parquet"), lambda tmp: pq.write_table(table, tmp))
    csv = atomic_write(stem.with_suffix(".csv"), lambda tmp: df.to_csv(tmp, index=False))
    return [parquet, csv]


def markdown_table(df: pd.DataFrame, digits: int = 3) -> str:
    """A DataFrame as a GitHub Markdown table, floats rounded to `digits`."""

    def cell(v: object) -> str:
        return f"{v:.{digits}f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(map(str, df.columns)) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"


def save_figure(fig: Figure, stem: Path, formats: Sequence[str] = ("png", "pdf"), dpi: int = 130) -> list[Path]:
    """A matplotlib Figure as `stem.<format>` for each format, each written atomically."""
    return [
        atomic_write(stem.with_name(f"{stem.name}.{fmt}"), lambda tmp, f=fmt: fig.savefig(tmp, format=f, dpi=dpi))  # type: ignore[misc]
        for fmt in formats
    ]
