"""`stafpipe plot KIND RUN_DIR`: figures drawn from a finished run directory, written as PNG and PDF into the plot run's
own directory (which, like every run directory, carries its resolved config)."""

from __future__ import annotations

import logging
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from stafpipe.config.schema import PlotConfig
from stafpipe.errors import StafpipeError
from stafpipe.io import atomic_write

log = logging.getLogger(__name__)


def run_plot(cfg: DictConfig, out_dir: Path) -> list[Path]:
    """Draw `plot.kind` from `plot.run_dir`; every input is read and checked before the first figure is written."""
    from stafpipe.episode_log import read_episode
    from stafpipe.plots.trajectories import episode_files, trajectory_figure

    pc: PlotConfig = OmegaConf.to_object(cfg.plot)  # type: ignore[assignment]
    pc.check()
    run_dir = Path(pc.run_dir)
    if not run_dir.is_dir():
        raise StafpipeError(f"plot.run_dir: no such directory: {run_dir}")
    files = episode_files(run_dir)
    if not files:
        raise StafpipeError(f"plot.run_dir: {run_dir} holds no episodes/*.mcap (is it an eval run with eval.log_episodes?)")
    if pc.max_episodes:
        files = files[: pc.max_episodes]
    records = [read_episode(f) for f in files]  # all read (and validated) before anything is written
    outputs: list[Path] = []
    for path, rec in zip(files, records, strict=True):
        fig = trajectory_figure(rec)
        for fmt in pc.formats:
            target = out_dir / f"trajectories_{path.stem}.{fmt}"
            outputs.append(atomic_write(target, lambda tmp, f=fmt: fig.savefig(tmp, format=f, dpi=pc.dpi)))
        log.info("drew %s", path.name)
    print("\n".join(str(p) for p in outputs))
    return outputs
