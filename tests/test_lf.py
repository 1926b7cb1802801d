"""`method=lf`: leader-follower keeps its formation in the open and, by design, gets stuck at a narrow corridor."""

from __future__ import annotations

import pandas as pd
import pytest

from conftest import job_dirs
from stafpipe.launch import launch


def _results(workdir, *overrides) -> pd.DataFrame:
    before = set(job_dirs(workdir))
    assert launch("eval", ["method=lf", "eval.episodes=1", *overrides]) == 0
    [run] = [d for d in job_dirs(workdir) if d not in before]
    return pd.read_parquet(run / "results.parquet")


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_lf_in_the_open_reaches_the_goal_in_formation_near_the_time_bound(workdir) -> None:
    r = _results(workdir, "scenario.obstacles=[]", "formation=wedge").iloc[0]
    assert r.sr == 1.0 and r.collisions == 0
    assert r.tt_ratio < 1.2  # within 20 % of the shortest-path time of the formation centre
    assert r["cfi_0.5"] > 0.85  # formation integrity kept (the corridor-width part of CFI does not apply here)


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_lf_gets_stuck_in_the_corridor_without_collisions(workdir) -> None:
    r = _results(workdir, "scenario.time_limit=60").iloc[0]
    assert r.collisions == 0  # the avoidance caps approach speeds: robots stop short of walls and of each other
    assert r.sr < 1.0  # no subteaming, no adaptation: the outer robots wait at the wall (STAF Section 4)
