"""TensorBoard event files of a training run, beside its CSV/Parquet curves: `tensorboard --logdir outputs/` shows
every run (each job of a sweep is its own directory, so its own run)."""

from __future__ import annotations

import math
from pathlib import Path

TB_DIR = "tensorboard"


class ScalarLog:
    """Writes the history rows (a PPO iteration, a graph-cut epoch) as TensorBoard scalars at step `row[step_key]`;
    keys such as `charts/success_rate` group in TensorBoard by their prefix, and `train_x` / `val_x` become `train/x` /
    `val/x`. One event file per run directory: an earlier (killed, resumed) session's files are removed when this
    one starts, and `sync` writes the whole history, the rows a resumed run took over included, so TensorBoard never
    shows the same step twice."""

    def __init__(self, out_dir: Path, step_key: str) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.step_key = step_key
        log_dir = Path(out_dir) / TB_DIR
        for old in log_dir.glob("events.out.tfevents.*"):
            old.unlink()
        self.writer = SummaryWriter(log_dir=str(log_dir))
        self.written = 0

    def sync(self, history: list[dict[str, float]]) -> None:
        """Write the rows of `history` not yet written by this log."""
        for row in history[self.written :]:
            step = int(row[self.step_key])
            for key, value in row.items():
                if key != self.step_key and isinstance(value, (int, float)) and math.isfinite(value):
                    self.writer.add_scalar(_tag(key), float(value), step)
        self.written = len(history)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


def _tag(key: str) -> str:
    for prefix in ("train_", "val_"):
        if key.startswith(prefix):
            return prefix[:-1] + "/" + key[len(prefix) :]
    return key
