"""`stafpipe plot video`: an MP4 and a GIF per episode of an eval run or of one .mcap file, one frame per `stride`
logged steps, robots in their subteam's colour; bad settings refused before anything is written."""

from __future__ import annotations

import dataclasses

import imageio.v2 as imageio
import numpy as np
import pytest
from matplotlib.colors import to_rgb
from typer.testing import CliRunner

from conftest import job_dirs
from stafpipe.cli import app
from stafpipe.episode_log import read_episode
from stafpipe.launch import launch
from stafpipe.plots.video import episode_frames, frame_indices


def _episode(workdir):
    assert launch("eval", ["method=straight", "scenario=corridor", "scenario.time_limit=3", "eval.episodes=1"]) == 0
    [run] = job_dirs(workdir / "outputs" / "eval")
    return run, run / "episodes" / "episode_0000.mcap"


def test_frame_indices_keep_the_first_and_the_last_step() -> None:
    assert frame_indices(10, 4) == [0, 4, 8, 9]
    assert frame_indices(9, 4) == [0, 4, 8]
    assert frame_indices(5, 1) == [0, 1, 2, 3, 4]
    assert len(frame_indices(31, 3)) == 11


@pytest.mark.slow  # an eval and two encoders: about 5 s on 2 cores
def test_video_of_an_eval_run_and_of_a_file_has_one_frame_per_stride(workdir) -> None:
    run, mcap = _episode(workdir)
    steps = len(read_episode(mcap).time)
    runner = CliRunner()
    result = runner.invoke(app, ["plot", "video", str(run), "plot.stride=4", "plot.width_px=320"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["plot", "video", str(mcap), "plot.stride=7", "plot.video_formats=[gif]"])
    assert result.exit_code == 0, result.output
    from_run, from_file = job_dirs(workdir / "outputs" / "plot")
    for path, stride in ((from_run / "video_episode_0000.mp4", 4), (from_run / "video_episode_0000.gif", 4)):
        frames = imageio.mimread(path, memtest=False)
        assert len(frames) == len(frame_indices(steps, stride)), path
        assert frames[0].shape[1] == 320
        assert not np.array_equal(frames[0], frames[-1])  # the robots moved and the clock ran
    assert len(imageio.mimread(from_file / "video_episode_0000.gif", memtest=False)) == len(frame_indices(steps, 7))
    assert not (from_file / "video_episode_0000.mp4").exists()
    assert not list(from_run.glob(".*tmp*"))
    (run / "episodes" / "episode_0001.mcap").write_bytes(b"not a log")  # every log is read before a video is written
    damaged = runner.invoke(app, ["plot", "video", str(run)])
    assert damaged.exit_code == 2 and "episode_0001.mcap" in damaged.output
    assert len(job_dirs(workdir / "outputs" / "plot")) == 2  # the failed run left no directory behind


def _share_of(frame: np.ndarray, colour: str) -> float:
    rgb = np.array(to_rgb(colour)) * 255
    return float((np.abs(frame.astype(float) - rgb).max(axis=-1) < 8).mean())


def test_robots_take_their_subteams_colour(workdir) -> None:
    _, mcap = _episode(workdir)
    rec = read_episode(mcap)
    subteams = rec.subteams.copy()
    half = len(subteams) // 2
    subteams[half:, 5:] = 1  # robots 5.. split off halfway
    frames = list(episode_frames(dataclasses.replace(rec, subteams=subteams), stride=half, width_px=480))
    before, after = frames[0], frames[1]
    assert _share_of(before, "C0") > 0 and _share_of(before, "C1") == 0
    assert _share_of(after, "C1") > 0


def test_bad_video_settings_are_refused_and_leave_nothing(workdir) -> None:
    run = workdir / "run"
    (run / "episodes").mkdir(parents=True)
    runner = CliRunner()
    for override, key in (
        ("plot.video_formats=[avi]", "plot.video_formats"),
        ("plot.stride=0", "plot.stride"),
        ("plot.fps=0", "plot.fps"),
    ):
        result = runner.invoke(app, ["plot", "video", str(run), override])
        assert result.exit_code == 2 and key in result.output, (override, result.output)
    empty = runner.invoke(app, ["plot", "video", str(run)])
    assert empty.exit_code == 2 and "holds no episodes/*.mcap" in empty.output
    assert not list((workdir / "outputs").rglob("video_*"))
