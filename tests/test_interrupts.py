"""A run interrupted by Ctrl-C or SIGTERM says so in one line, exits 130 and leaves nothing a rerun could mix with
its own results; a rerun into the directory of an earlier run starts it over cleanly."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from stafpipe.launch import launch


def _episodes_started(run: Path, timeout: float = 60.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if list(run.glob("episodes/*")):
            return True
        time.sleep(0.1)
    return False


@pytest.mark.slow  # a subprocess that imports the package and runs episodes: about 8 s
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_eval_says_so_and_leaves_no_episode_logs(tmp_path, sig) -> None:
    run = tmp_path / "run"
    words = [
        "eval",
        "method=straight",
        "scenario=corridor",
        "eval.episodes=200",
        "eval.batch=1",
        f"hydra.run.dir={run}",
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "stafpipe", *words],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert _episodes_started(run), "the run never began its episodes"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert "interrupted: eval" in err and "Traceback" not in err
    assert not (run / "stage.json").exists() and not list(run.glob("episodes/*")) and not list(run.rglob("*.part"))


@pytest.mark.slow  # two evaluations: about 5 s
def test_a_rerun_into_an_earlier_runs_directory_keeps_none_of_its_episodes(workdir) -> None:
    run = workdir / "run"
    assert launch("eval", ["method=straight", "scenario=corridor", "eval.episodes=3", f"hydra.run.dir={run}"]) == 0
    (run / "episodes" / "episode_0099.mcap").write_bytes(b"left by a killed run")  # an episode the rerun will not write
    (run / "episodes" / "episode_0100.mcap.part").write_bytes(b"")
    (run / ".results.csv.tmp-4242").write_text("a table a killed run was writing")
    (run / "notes.txt").write_text("the user's own")
    assert launch("eval", ["method=straight", "scenario=corridor", "eval.episodes=2", f"hydra.run.dir={run}"]) == 0
    assert sorted(p.name for p in (run / "episodes").iterdir()) == ["episode_0000.mcap", "episode_0001.mcap"]
    assert not list(run.glob(".*.tmp-*"))
    assert (run / "notes.txt").read_text() == "the user's own"


@pytest.mark.slow  # a subprocess that imports the package and runs episodes: about 8 s
def test_a_sigkilled_eval_then_a_rerun_leaves_only_the_reruns_results(tmp_path) -> None:
    """SIGKILL gives the run no chance to clean up: its lock, `.part` logs and finished episodes stay behind. The same
    command again takes the directory over (the lock's process is dead), removes all of it, and ends with the results
    and logs of its own episodes only."""
    run = tmp_path / "run"
    words = ["eval", "method=straight", "scenario=corridor", "eval.batch=1", f"hydra.run.dir={run}"]
    proc = subprocess.Popen([sys.executable, "-m", "stafpipe", *words, "eval.episodes=200"], cwd=tmp_path)
    assert _episodes_started(run), "the run never began its episodes"
    time.sleep(1.0)
    proc.kill()
    proc.wait(timeout=60)
    assert not (run / "stage.json").exists()
    assert launch("eval", [*words[1:], "eval.episodes=2"]) == 0
    assert sorted(p.name for p in (run / "episodes").iterdir()) == ["episode_0000.mcap", "episode_0001.mcap"]
    assert not list(run.rglob("*.part")) and not list(run.glob(".*.tmp-*"))
    assert (run / "stage.json").is_file() and len(pd.read_parquet(run / "results.parquet")) == 2
