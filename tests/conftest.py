"""Shared fixtures: every test runs in its own temporary working directory, so outputs/ lands there."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh current directory for a test's outputs/."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def job_dirs(root: Path) -> list[Path]:
    """Every finished stage run directory (those holding a stage.json marker) under `root`."""
    return sorted(p.parent for p in root.rglob("stage.json"))


def tensorboard_scalars(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar of a run's TensorBoard event files, read back with TensorBoard's own reader."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir / "tensorboard"))
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}
