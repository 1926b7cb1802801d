"""`stafpipe plot regions|timing RUN_DIR` on an eval run of method=zhu: Zhu's Fig. 4 snapshots and Table I."""

from __future__ import annotations

import pandas as pd
import pytest
from typer.testing import CliRunner

from conftest import job_dirs
from stafpipe.cli import app
from stafpipe.launch import launch
from stafpipe.plots.zhu import TIMED_PARTS, timing_table


def _zhu_run(workdir):
    assert (
        launch(
            "eval",
            ["method=zhu", "scenario=corridor", "scenario.time_limit=5", "eval.episodes=2", "sensing.radius=3.0"],
        )
        == 0
    )
    [run] = job_dirs(workdir / "outputs" / "eval")
    return run


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_regions_snapshots_and_timing_table_from_a_zhu_run(workdir) -> None:
    run = _zhu_run(workdir)
    results = pd.read_parquet(run / "results.parquet")
    table = timing_table(results)
    assert len(table) == len(TIMED_PARTS) + 1
    regions = table.set_index("Computations").loc["Convex regions"]
    assert 0 < regions["Min."] <= regions["Mean."] <= regions["Max."]
    assert regions["cycles"] == results["time_convex_regions_count"].sum() > 0
    runner = CliRunner()
    drawn = runner.invoke(app, ["plot", "regions", str(run), "plot.max_episodes=1", "plot.times=[1.0,4.0]"])
    assert drawn.exit_code == 0, drawn.output
    tabled = runner.invoke(app, ["plot", "timing", str(run)])
    assert tabled.exit_code == 0, tabled.output
    region_run, timing_run = sorted(job_dirs(workdir / "outputs" / "plot"))
    assert (region_run / "regions_episode_0000.png").read_bytes()[:4] == b"\x89PNG"
    assert not (region_run / "regions_episode_0001.png").exists()
    md, tex = (timing_run / "timing.md").read_text(), (timing_run / "timing.tex").read_text()
    assert "| Convex regions |" in md and "Total (sum of means)" in md
    assert r"\begin{tabular}" in tex and "Graph partition" in tex


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_timing_of_a_run_without_zhu_is_refused_and_writes_nothing(workdir) -> None:
    assert launch("eval", ["method=straight", "scenario=corridor", "scenario.time_limit=3", "eval.episodes=1"]) == 0
    [run] = job_dirs(workdir / "outputs" / "eval")
    runner = CliRunner()
    out = runner.invoke(app, ["plot", "timing", str(run)])
    assert out.exit_code == 2 and "timing columns" in out.output
    regions = runner.invoke(app, ["plot", "regions", str(run)])
    assert regions.exit_code == 2 and "regions" in regions.output
    assert not (workdir / "outputs" / "plot").exists() or not list((workdir / "outputs" / "plot").rglob("timing.md"))
