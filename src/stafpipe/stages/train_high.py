"""`stafpipe train-high`: train STAF's deep graph cut on the synthetic teams of `stafpipe generate`.

Writes `high_level.pt` (the checkpoint: weights, the `high` config, and how it was made), `losses.parquet/.csv` (loss
terms per epoch, training and validation) and `loss_curves.png/.pdf`. `last.pt` holds the full training state after each
epoch: rerunning the same config in the same directory (what `stafpipe run` does) resumes a killed run.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pandas as pd
from omegaconf import DictConfig

from stafpipe.config.schema import DataConfig, FormationConfig
from stafpipe.errors import StafpipeError
from stafpipe.highlevel.config import HighLevelConfig, TrainHighConfig
from stafpipe.io import save_figure, write_table
from stafpipe.sections import section

log = logging.getLogger(__name__)
REQUIRED_COLUMNS = ("instance", "robot", "x", "y", "goal_x", "goal_y")


def load_formations(path: str) -> pd.DataFrame:
    """A `formations.parquet` (or CSV) of `stafpipe generate`, or the run directory holding one; checked for its
    columns."""
    p = Path(path)
    if p.is_dir():
        p = p / "formations.parquet"
    if not p.is_file():
        raise StafpipeError(f"train_high.data: no such file: {p}")
    try:
        df = pd.read_parquet(p) if p.suffix == ".parquet" else pd.read_csv(p)
    except Exception as exc:  # noqa: BLE001 (pyarrow and pandas raise several kinds for a damaged file)
        raise StafpipeError(f"train_high.data: {p} is not a readable table ({type(exc).__name__}: {exc})") from None
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise StafpipeError(f"train_high.data: {p} lacks columns {missing} (see docs/data.md)")
    if df[list(REQUIRED_COLUMNS)].isna().any().any():
        raise StafpipeError(f"train_high.data: {p} has missing values in {list(REQUIRED_COLUMNS)}")
    return df


def run_train_high(cfg: DictConfig, out_dir: Path) -> list[Path]:
    from stafpipe.highlevel.graphs import team_graph, teams_from_frame
    from stafpipe.highlevel.instances import generate_instances
    from stafpipe.highlevel.training import train
    from stafpipe.launch import config_hash
    from stafpipe.plots.training import loss_curve_figure
    from stafpipe.tensorboard_log import TB_DIR, ScalarLog

    high = section(cfg.high, HighLevelConfig)
    tc = section(cfg.train_high, TrainHighConfig)
    high.check()
    tc.check()
    if max(tc.m_choices) > high.m_max:
        raise StafpipeError(f"train_high.m_choices {list(tc.m_choices)} exceed high.m_max ({high.m_max})")
    if tc.data:
        df = load_formations(tc.data)
    else:
        data = section(cfg.data, DataConfig)
        formation = section(cfg.formation, FormationConfig)
        df = generate_instances(data, formation, int(cfg.seed))
    teams = teams_from_frame(df, 2)  # m is drawn per epoch in training
    graphs = [team_graph(t, high.features, high.radius) for t in teams]
    log.info("training the deep graph cut on %d teams (%d robots)", len(graphs), len(df))
    made_by = {"data": tc.data or "generated in memory from `data`", "teams": len(graphs)}
    board = ScalarLog(out_dir, "epoch")
    try:
        _, history = train(graphs, high, tc, int(cfg.seed), out_dir, config_hash(cfg), made_by, board.sync)
        board.sync(history)  # a resumed run with no epoch left to train writes the history it took over
    finally:
        board.close()
    outputs = [out_dir / "high_level.pt", out_dir / "last.pt"]
    outputs += sorted((out_dir / TB_DIR).iterdir())
    outputs += write_table(pd.DataFrame(history), out_dir / "losses")
    outputs += save_figure(loss_curve_figure(history), out_dir / "loss_curves", dpi=120)
    final = history[-1]
    log.info("final losses: %s", {k: round(v, 4) for k, v in final.items()})
    return outputs
