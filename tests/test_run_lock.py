"""One run per run directory: a live run's lock refuses a second run; a killed run's lock does not block a rerun."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

from stafpipe.launch import launch
from stafpipe.run_lock import LOCK

FAST = ["method=straight", "scenario=corridor", "eval.episodes=1", "scenario.time_limit=2"]


def test_a_directory_in_use_is_refused_and_left_as_it_was(workdir, capsys) -> None:
    run = workdir / "busy"
    run.mkdir()
    (run / LOCK).write_text(f"{socket.gethostname()} {os.getppid()}")  # a live process holds it
    (run / "episodes").mkdir()
    (run / "episodes" / "episode_0000.mcap").write_bytes(b"the other run's log")
    assert launch("eval", [*FAST, f"hydra.run.dir={run}"]) == 2
    assert "in use by another run" in capsys.readouterr().err
    assert (run / "episodes" / "episode_0000.mcap").read_bytes() == b"the other run's log"
    assert (run / LOCK).is_file() and not (run / "stage.json").exists()


def test_a_killed_runs_lock_does_not_block_the_rerun(workdir) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    run = workdir / "after-kill"
    run.mkdir()
    (run / LOCK).write_text(f"{socket.gethostname()} {int(dead.stdout)}")
    assert launch("eval", [*FAST, f"hydra.run.dir={run}"]) == 0
    assert (run / "stage.json").is_file() and not (run / LOCK).exists()
