"""`stafpipe generate`: the synthetic formation instances that train STAF's high level
(`highlevel/instances.py`), written as a table (docs/data.md)."""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig

from stafpipe.config.schema import DataConfig, FormationConfig
from stafpipe.highlevel.instances import generate_instances
from stafpipe.io import write_table
from stafpipe.sections import section

log = logging.getLogger(__name__)
SCHEMA_VERSION = "1"


def run_generate(cfg: DictConfig, out_dir: Path) -> list[Path]:
    """Write `formations.parquet` (+ `.csv`) into `out_dir`."""
    data = section(cfg.data, DataConfig)
    formation = section(cfg.formation, FormationConfig)
    df = generate_instances(data, formation, int(cfg.seed))
    meta = {"stafpipe.schema_version": SCHEMA_VERSION, "stafpipe.seed": str(cfg.seed)}
    outputs = write_table(df, out_dir / "formations", metadata=meta)
    log.info("wrote %d instances (%d robots) to %s", data.instances, len(df), outputs[0])
    return outputs
