"""High-level checkpoints: the network's weights with the config that shapes it and a record of how it was made.

A checkpoint is one `torch.save` file holding plain data only (loaded with `weights_only=True`): `format`, `high` (the
HighLevelConfig fields), `state_dict`, and `made_by` (training config, seed, stafpipe version, commit, final losses).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from stafpipe.errors import StafpipeError
from stafpipe.highlevel.config import HighLevelConfig
from stafpipe.highlevel.model import DeepGraphCut
from stafpipe.paths import package_dir
from stafpipe.torch_io import load_payload, save_payload

FORMAT = "stafpipe.high_level/1"
SHIPPED = "checkpoints/high_level.pt"


class CheckpointError(StafpipeError):
    """A checkpoint that is missing, damaged, or not a high-level checkpoint of this format."""


def shipped_path() -> Path:
    """The high-level checkpoint that ships inside the package."""
    return package_dir() / SHIPPED


def save_checkpoint(path: Path, model: DeepGraphCut, made_by: dict[str, Any]) -> Path:
    """Write atomically: a killed save never leaves a half-written checkpoint."""
    payload = {
        "format": FORMAT,
        "high": dataclasses.asdict(model.cfg),
        "state_dict": model.state_dict(),
        "made_by": made_by,
    }
    return save_payload(Path(path), payload)


def load_checkpoint(
    path: str | Path = "", overrides: HighLevelConfig | None = None
) -> tuple[DeepGraphCut, dict[str, Any]]:
    """The network of a checkpoint (the shipped one when `path` is empty), in eval mode, and its `made_by` record.

    The architecture comes from the checkpoint; `overrides` only supplies inference settings (m, safe_gap, checkpoint).
    """
    path = Path(path) if path else shipped_path()
    payload = load_payload(path, CheckpointError, "checkpoint")
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise CheckpointError(f"{path}: not a stafpipe high-level checkpoint (format {found!r}, expected {FORMAT!r})")
    try:
        cfg = HighLevelConfig(**payload["high"])
    except TypeError as exc:
        raise CheckpointError(f"{path}: its `high` config does not match this version ({exc})") from None
    if overrides is not None:
        cfg = dataclasses.replace(cfg, m=overrides.m, safe_gap=overrides.safe_gap, checkpoint=str(path))
    model = DeepGraphCut(cfg)
    try:
        model.load_state_dict(payload["state_dict"])
    except (RuntimeError, KeyError) as exc:
        raise CheckpointError(f"{path}: weights do not fit the network its config describes ({exc})") from None
    model.eval()
    return model, payload.get("made_by", {})
