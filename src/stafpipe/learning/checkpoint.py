"""Policy checkpoints: weights, the policy config, and how they were made (plain data, `weights_only` loading)."""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path
from typing import Any

import torch

from stafpipe.errors import StafpipeError
from stafpipe.io import atomic_write
from stafpipe.learning.config import PolicyConfig
from stafpipe.learning.dgnn import DGNNPolicy
from stafpipe.paths import package_dir

FORMAT = "stafpipe.policy/1"


class PolicyCheckpointError(StafpipeError):
    """A policy checkpoint that is missing, damaged or of another kind."""


def shipped_policy(method: str) -> Path:
    return package_dir() / "checkpoints" / f"{method}.pt"


def save_policy(path: Path, method: str, policy: DGNNPolicy, made_by: dict[str, Any]) -> Path:
    payload = {"format": FORMAT, "method": method, "policy": dataclasses.asdict(policy.cfg),
               "state_dict": policy.state_dict(), "made_by": made_by}
    buf = io.BytesIO()
    torch.save(payload, buf)
    return atomic_write(Path(path), lambda tmp: tmp.write_bytes(buf.getvalue()))


def load_policy(path: str | Path, method: str) -> tuple[DGNNPolicy, dict[str, Any]]:
    """The policy of a checkpoint (`path` empty: the one shipped for `method`), in eval mode, and its record."""
    path = Path(path) if path else shipped_policy(method)
    if not path.is_file():
        raise PolicyCheckpointError(f"{path}: no such policy checkpoint (train one with `stafpipe train-ppo`)")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises several kinds for a damaged file
        raise PolicyCheckpointError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT or payload.get("method") != method:
        found = (payload.get("format"), payload.get("method")) if isinstance(payload, dict) else type(payload).__name__
        raise PolicyCheckpointError(f"{path}: not a stafpipe {method} policy checkpoint (found {found})")
    try:
        policy = DGNNPolicy(PolicyConfig(**payload["policy"]))
        policy.load_state_dict(payload["state_dict"])
    except (TypeError, RuntimeError, KeyError) as exc:
        raise PolicyCheckpointError(f"{path}: weights do not fit the policy its config describes ({exc})") from None
    policy.eval()
    return policy, payload.get("made_by", {})
