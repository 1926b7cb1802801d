import pytest

from conftest import job_dirs
from stafpipe.errors import StafpipeError
from stafpipe.pipeline import run_pipeline


@pytest.mark.slow  # over 10 s on 2 cores
def test_smoke_runs_then_skips_then_forces(workdir, capsys) -> None:
    assert run_pipeline("smoke") == 0
    first = {d: (d / "stage.json").stat().st_mtime_ns for d in job_dirs(workdir)}
    assert len(first) == 8 and len(list(workdir.rglob("episodes/*.mcap"))) == 4
    assert len(list(workdir.rglob("*-plot-straight-*/trajectories_episode_0000.png"))) == 1
    capsys.readouterr()
    assert run_pipeline("smoke") == 0
    out = capsys.readouterr().out
    assert out.count("skipped") == 8
    assert {d: (d / "stage.json").stat().st_mtime_ns for d in job_dirs(workdir)} == first
    assert run_pipeline("smoke", force=True) == 0
    assert all((d / "stage.json").stat().st_mtime_ns != t for d, t in first.items())


def _write(workdir, text: str):
    path = workdir / "p.yaml"
    path.write_text(text)
    return str(path)


def test_failing_step_stops_the_pipeline(workdir, capsys) -> None:
    path = _write(
        workdir,
        "steps:\n"
        "  - {name: ok, stage: generate, overrides: [experiment=smoke]}\n"
        "  - {name: bad, stage: generate, overrides: [experiment=smoke, data.n_min=1]}\n"
        "  - {name: never, stage: generate, overrides: [experiment=smoke, seed=9]}\n",
    )
    assert run_pipeline(path) != 0
    assert "bad (generate): failed" in capsys.readouterr().out
    assert len(job_dirs(workdir)) == 1


def test_step_reference_and_bad_files(workdir) -> None:
    with pytest.raises(StafpipeError, match="stage"):
        run_pipeline(_write(workdir, "steps:\n  - {stage: fly}\n"))
    with pytest.raises(StafpipeError, match="not an earlier step"):
        run_pipeline(_write(workdir, "steps:\n  - {stage: generate, overrides: ['+x={steps.later.dir}']}\n"))
    with pytest.raises(StafpipeError, match="bad config"):
        run_pipeline(_write(workdir, "steps:\n  - {stage: generate, overrides: [wrong=1]}\n"))
    with pytest.raises(StafpipeError, match="no pipeline"):
        run_pipeline("does-not-exist")


@pytest.mark.slow  # over 5 s on 2 cores
def test_step_reruns_when_a_file_it_reads_changes(workdir, capsys) -> None:
    # The config hash is the same, but the map the step reads was edited: the old result must not be reused.
    from pathlib import Path

    scenario = workdir / "map.yaml"
    scenario.write_text((Path(__file__).parent / "data" / "s_example.yaml").read_text())
    path = _write(workdir, "steps:\n  - {name: e, stage: eval, overrides: [experiment=smoke, method=straight, "
                           f"'scenario.path={scenario}', scenario.time_limit=3, eval.episodes=1]}}\n")
    assert run_pipeline(path) == 0
    assert run_pipeline(path) == 0
    assert capsys.readouterr().out.count("skipped") == 1
    scenario.write_text(scenario.read_text() + "\n# edited\n")
    assert run_pipeline(path) == 0
    assert capsys.readouterr().out.count("skipped") == 0
