"""Saving and loading torch payloads (checkpoints, training states): atomic writes, plain-data loads, clear errors."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import torch

from stafpipe.errors import StafpipeError
from stafpipe.io import atomic_write


def save_payload(path: Path, payload: dict[str, Any]) -> Path:
    """`torch.save` into a temporary sibling, then rename: a killed save never leaves a half-written file."""
    buf = io.BytesIO()
    torch.save(payload, buf)
    return atomic_write(Path(path), lambda tmp: tmp.write_bytes(buf.getvalue()))


def load_payload(path: Path, error: type[StafpipeError], what: str, hint: str = "") -> Any:
    """The plain data in a torch file (`weights_only`: no code runs); `error` naming the file if it is missing or
    damaged."""
    if path.is_dir():
        inside = sorted(q.name for q in path.glob("*.pt"))
        example = f" (it holds {', '.join(inside[:3])})" if inside else ""
        raise error(f"{path} is a directory, not a {what}; name the file{example}")
    if not path.is_file():
        raise error(f"{path}: no such {what}" + (f" ({hint})" if hint else ""))
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 (torch raises several kinds for a damaged file)
        raise error(f"{path}: not a readable {what} ({type(exc).__name__}: {exc})") from None


def training_device(name: str, key: str) -> torch.device:
    """The torch device a training stage asked for (`cpu`, `cuda` or `cuda:N`), checked again here for callers that
    skip the config check (the project never needs one; the simulator always runs on the CPU)."""
    from stafpipe.devices import check_device

    check_device(name, key)
    return torch.device(name)
