"""TensorBoard event files of a training run, beside its CSV/Parquet curves: `tensorboard --logdir outputs/` shows
every run (each job of a sweep is its own directory, so its own run)."""

from __future__ import annotations

import math
from pathlib import Path

TB_DIR = "tensorboard"


class ScalarLog:
    """Writes one history row at a time (a PPO iteration, a graph-cut epoch) as TensorBoard scalars at step
    `row[step_key]`; keys such as `charts/success_rate` group in TensorBoard by their prefix, and `train_x` / `val_x`
    become `train/x` / `val/x`."""

    def __init__(self, out_dir: Path, step_key: str) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.step_key = step_key
        self.writer = SummaryWriter(log_dir=str(Path(out_dir) / TB_DIR))

    def write(self, row: dict[str, float]) -> None:
        step = int(row[self.step_key])
        for key, value in row.items():
            if key != self.step_key and isinstance(value, (int, float)) and math.isfinite(value):
                self.writer.add_scalar(_tag(key), float(value), step)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


def _tag(key: str) -> str:
    for prefix in ("train_", "val_"):
        if key.startswith(prefix):
            return prefix[:-1] + "/" + key[len(prefix) :]
    return key
