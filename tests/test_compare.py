"""`stafpipe compare`: every method on one map given by path, in one directory (table, trajectory figure and video
per method, compare.md), a method that cannot run it said so, a rerun skipping what is done; `plot table` on a
multirun directory."""

from __future__ import annotations

import pandas as pd
import pytest
from typer.testing import CliRunner

from conftest import job_dirs
from stafpipe.cli import app
from stafpipe.launch import launch

SMOKE = ["scenario.time_limit=3", "eval.episodes=1"]
MAP = "world: {xmin: 0, ymin: -3, xmax: 9, ymax: 3}\nteam: {n: 4, formation: line, start: [2, 0], goal: [7, 0]}\n"
"time_limit: 4\n"


@pytest.mark.slow  # three evals, four figures, two videos: about 15 s on 2 cores
def test_compare_on_a_map_by_path(workdir) -> None:
    (workdir / "my_map.yaml").write_text(MAP)
    args = [
        "compare",
        "--methods",
        "straight,lf,cezayirli",
        f"scenario.path={workdir / 'my_map.yaml'}",
        "eval.episodes=1",
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    home = workdir / "outputs" / "pipelines" / "compare-my_map"
    index = (home / "compare.md").read_text()
    assert "| straight | ran |" in index and "| lf | ran |" in index
    assert "| cezayirli | cannot run it (exit code 2): method.d_max/sensing.radius" in index  # its own sensor: said
    [table] = home.glob("*-table-*")
    rows = pd.read_csv(table / "table.csv")
    assert sorted(rows["method"]) == ["lf", "straight"]
    for method in ("straight", "lf"):
        [traj] = home.glob(f"*-trajectories-{method}-*")
        [video] = home.glob(f"*-video-{method}-*")
        assert (traj / "trajectories_episode_0000.png").is_file()
        assert (video / "video_episode_0000.mp4").stat().st_size > 0
    again = CliRunner().invoke(app, args)
    assert again.exit_code == 0 and again.output.count("skipped, already done") == 2 + 5  # two evals, five plots


def test_compare_refuses_bad_input_before_any_work(workdir) -> None:
    runner = CliRunner()
    for args, says in (
        (["compare", "--methods", "straight,nosuch"], "--methods: unknown method(s) ['nosuch']"),
        (["compare", "--methods", "straight", "--videos", "-1"], "--videos: must be >= 0"),
        (["compare", "--methods", "straight", "--name", "../up"], "--name: '../up' may hold only"),
        (["compare", "--methods", "straight", f"scenario.path={workdir / 'nope.yaml'}"], "nope.yaml"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 2 and says in result.output, (args, result.output)
    assert not list((workdir / "outputs").rglob("compare-*"))


@pytest.mark.slow  # a two-job sweep: about 5 s
def test_plot_table_reads_a_multirun_directory(workdir) -> None:
    assert launch("eval", ["-m", "method=straight,lf", "scenario=corridor", *SMOKE]) == 0
    [sweep] = (workdir / "outputs" / "multirun" / "eval").glob("*/*")
    result = CliRunner().invoke(app, ["plot", "table", str(sweep)])
    assert result.exit_code == 0, result.output
    [plot_run] = job_dirs(workdir / "outputs" / "plot")
    assert sorted(pd.read_csv(plot_run / "table.csv")["method"]) == ["lf", "straight"]
    (sweep / "1" / "results.parquet").unlink()  # a job that did not finish
    broken = CliRunner().invoke(app, ["plot", "table", str(sweep)])
    assert broken.exit_code == 2 and "jobs ['1'] hold no results.parquet" in broken.output
