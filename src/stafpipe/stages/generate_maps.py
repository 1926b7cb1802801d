"""`stafpipe generate-maps`: seeded procedural training maps (stafpipe.mapgen), one scenario YAML per map.

Writes `maps/map_NNNN.yaml` (map k of the run, its scenario named `gen<seed>_<k>-<family>`; each readable by
`scenario.path=` and usable as a `train_ppo.scenarios` entry, or the whole `maps/` directory as one entry) and
`maps.parquet/.csv` (one row per map: file, name, family, team size, formation, drive, world size, obstacle count).
"""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd
from omegaconf import DictConfig, OmegaConf

from stafpipe.io import atomic_write, write_table
from stafpipe.mapgen import MapsConfig, generate_maps
from stafpipe.sections import section

log = logging.getLogger(__name__)


def run_generate_maps(cfg: DictConfig, out_dir: Path) -> list[Path]:
    maps_cfg = section(cfg.maps, MapsConfig)
    maps_cfg.check()
    specs = generate_maps(maps_cfg, int(cfg.seed))
    outputs, rows = [], []
    for k, spec in enumerate(specs):
        text = OmegaConf.to_yaml(OmegaConf.structured(spec))
        outputs.append(atomic_write(out_dir / "maps" / f"map_{k:04d}.yaml", lambda tmp, t=text: tmp.write_text(t)))  # type: ignore[misc]
        rows.append(
            {
                "file": f"maps/map_{k:04d}.yaml",
                "name": spec.name,
                "family": spec.name.rsplit("-", 1)[-1],
                "n": spec.team.n,
                "formation": spec.team.formation,
                "drive": spec.robot.drive,
                "length": spec.world.xmax,
                "height": spec.world.ymax,
                "obstacles": len(spec.obstacles),
            }
        )
    outputs += write_table(pd.DataFrame(rows), out_dir / "maps")
    log.info("%d maps in %s", len(specs), out_dir / "maps")
    return outputs
