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
