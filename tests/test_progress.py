"""Long stages are never silent without a terminal: progress lines at least every EVERY seconds, also while one slow
item is still running, with what is done, the rate and the time left."""

from __future__ import annotations

import logging
import time

import stafpipe.progress as progress_module
from stafpipe.progress import progress


def test_progress_logs_while_a_slow_item_runs_and_at_the_end(monkeypatch, caplog) -> None:
    monkeypatch.setattr(progress_module, "EVERY", 0.05)
    caplog.set_level(logging.INFO, logger="stafpipe.progress")
    bar = progress(range(3), desc="eval staf_planned on corridor", unit="episode")
    for k in bar:
        time.sleep(0.3 if k == 1 else 0.01)  # the second item is slow: lines must come while it runs
        bar.set_postfix(sr="1.00")
    lines = [r.getMessage() for r in caplog.records]
    during = [line for line in lines if line.startswith("eval staf_planned on corridor: 1/3 episodes")]
    assert len(during) >= 3, lines
    assert "ETA" in during[-1] and "elapsed" in during[-1]
    assert lines[-1].startswith("eval staf_planned on corridor: 3/3 episodes") and "(sr=1.00)" in lines[-1]


def test_progress_resumes_from_initial() -> None:
    bar = progress(range(5, 8), desc="train-high", unit="epoch", initial=5, total=8)
    assert list(bar) == [5, 6, 7] and bar.total == 8
