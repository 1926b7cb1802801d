"""docs/cli.md is the command line's reference as Typer writes it from the commands (`typer stafpipe.cli utils docs`):
a command or option changed without regenerating the page fails here."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

DOC = Path(__file__).parents[1] / "docs" / "cli.md"
COMMAND = [sys.executable, "-m", "typer", "stafpipe.cli", "utils", "docs", "--name", "stafpipe", "--output"]


def test_the_cli_reference_is_generated_from_the_commands(tmp_path) -> None:
    out = tmp_path / "cli.md"
    subprocess.run([*COMMAND, str(out)], check=True, capture_output=True, timeout=120)
    assert out.read_text() == DOC.read_text(), (
        "docs/cli.md is stale: python -m typer stafpipe.cli utils docs --name stafpipe --output docs/cli.md"
    )
