"""`stafpipe plot trajectories RUN_DIR`: figures from episode logs, clear errors on bad input, nothing half-written."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgba
from matplotlib.patches import Polygon
from typer.testing import CliRunner

from conftest import job_dirs
from stafpipe.cli import app
from stafpipe.episode import scenario_from_yaml
from stafpipe.episode_log import read_episode
from stafpipe.launch import launch
from stafpipe.plots.trajectories import trajectory_figure


def _eval_run(workdir):
    assert launch("eval", ["method=straight", "scenario=corridor", "scenario.time_limit=6", "eval.episodes=2"]) == 0
    [run] = job_dirs(workdir / "outputs" / "eval")
    return run


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_plot_trajectories_writes_png_and_pdf_per_episode(workdir) -> None:
    run = _eval_run(workdir)
    result = CliRunner().invoke(app, ["plot", "trajectories", str(run), "plot.max_episodes=1"])
    assert result.exit_code == 0, result.output
    [plot_run] = job_dirs(workdir / "outputs" / "plot")
    png, pdf = plot_run / "trajectories_episode_0000.png", plot_run / "trajectories_episode_0000.pdf"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and pdf.read_bytes()[:5] == b"%PDF-"
    assert not (plot_run / "trajectories_episode_0001.png").exists()  # max_episodes=1
    assert "run_dir: " + str(run) in (plot_run / "config.yaml").read_text()


def test_subteams_are_coloured_and_obstacles_drawn(workdir) -> None:
    rec = read_episode(next((_eval_run(workdir) / "episodes").glob("*.mcap")))
    subteams = rec.subteams.copy()
    subteams[len(subteams) // 2 :, 5:] = 1  # robots 5.. split off halfway
    fig = trajectory_figure(dataclasses.replace(rec, subteams=subteams))
    ax = fig.axes[0]
    lines = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(lines) == rec.positions.shape[1]
    first, split = (np.unique(c.get_colors(), axis=0) for c in (lines[0], lines[7]))
    assert len(first) == 1 and np.allclose(first[0], to_rgba("C0"))
    assert len(split) == 2  # C0 before the split, C1 after
    grey = [p for p in ax.patches if isinstance(p, Polygon)]
    assert len(grey) == len(scenario_from_yaml(rec.scenario_yaml).polygons)


def test_bad_run_dir_is_a_clear_error_and_leaves_nothing(workdir) -> None:
    runner = CliRunner()
    missing = runner.invoke(app, ["plot", "trajectories", str(workdir / "nope")])
    assert missing.exit_code == 2 and "plot.run_dir: no such directory" in missing.output
    (workdir / "empty").mkdir()
    empty = runner.invoke(app, ["plot", "trajectories", str(workdir / "empty")])
    assert empty.exit_code == 2 and "holds no episodes" in empty.output
    bad_kind = runner.invoke(app, ["plot", "scatter", str(workdir / "empty")])
    assert bad_kind.exit_code == 2 and "plot.kind must be one of" in bad_kind.output
    left = [p for p in workdir.rglob("*") if p.is_file()]
    assert not left, f"failed plot runs left files behind: {left}"
