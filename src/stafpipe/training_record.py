"""What a trained checkpoint records about how it was made."""

from __future__ import annotations

import subprocess
from pathlib import Path


def commit() -> str:
    """The git commit of the running code (`-dirty` when the tree has changes), or `unknown` outside a checkout."""
    try:
        out = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=40"],
            capture_output=True,
            text=True,
            timeout=5,
            cwd=Path(__file__).parent,
        )
        return out.stdout.strip() if out.returncode == 0 else "unknown"
    except OSError:
        return "unknown"
