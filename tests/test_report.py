"""The reproduction report: verdicts computed from numbers, claims read from run directories, pipelines that include
pipelines."""

import math

import pandas as pd
import pytest
import yaml

from conftest import job_dirs
from stafpipe.errors import StafpipeError
from stafpipe.pipeline import load_pipeline, run_pipeline
from stafpipe.report.claims_staf import staf_claims
from stafpipe.report.evidence import gather
from stafpipe.report.render import all_claims, judge_all
from stafpipe.report.verdicts import FAILS, HOLDS, MISSING, PARTLY, Criterion, Number


@pytest.mark.parametrize(
    ("criterion", "below", "at", "far"),
    [
        (Criterion("at_least", 95, 10), 94.9, 95.0, 84.9),
        (Criterion("at_most", 0, 1), 0.01, 0.0, 1.01),
        (Criterion("near", 40, 15), 55.1, 55.0, 70.1),
    ],
)
def test_a_verdict_changes_when_its_number_crosses_the_criterion(criterion, below, at, far) -> None:
    assert criterion.verdict(Number(at)) == HOLDS
    assert criterion.verdict(Number(below)) == PARTLY
    assert criterion.verdict(Number(far)) == FAILS
    assert criterion.verdict(Number(math.nan)) == MISSING


def test_comparisons_need_the_numbers_apart_beyond_both_cis() -> None:
    above = Criterion("above", 50.0, target_ci=2.0)
    assert above.verdict(Number(53.0, 0.5)) == HOLDS
    assert above.verdict(Number(52.0, 0.5)) == PARTLY  # inside the other's CI
    assert above.verdict(Number(49.0)) == FAILS
    below = Criterion("below", 1.0, target_ci=0.1)
    assert below.verdict(Number(0.8, 0.05)) == HOLDS and below.verdict(Number(0.95)) == PARTLY
    assert below.verdict(Number(1.2)) == FAILS
    with pytest.raises(ValueError, match="kind"):
        Criterion("about", 1.0)


def _eval_run(root, name, rows, faults=()) -> str:
    run = root / name
    run.mkdir()
    config = {"stage": "eval", "world": {"faults": list(faults)}, "sensing": {"occlusion": False}}
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    pd.DataFrame(rows).to_csv(run / "results.csv", index=False)
    (run / "stage.json").write_text("{}")
    return str(run)


def _episodes(method, formation, sr, n=10, episodes=5):
    base = {
        "method": method,
        "label": "",
        "scenario": "corridor",
        "formation": formation,
        "n": n,
        "drive": "holonomic",
        "subteams_max": 2,
    }
    return [{**base, "episode": i, "sr": sr, "cfi_0.5": 0.5, "cfi_printed_0.5": 0.4} for i in range(episodes)]


def test_a_claim_is_judged_from_the_runs_that_match_it_and_flips_with_its_number(tmp_path) -> None:
    claim = next(c for c in staf_claims() if c.statement == "STAF-planned (ours) success rate, wedge")
    good = _eval_run(tmp_path, "good", _episodes("staf_planned", "wedge", 1.0))
    other = _eval_run(tmp_path, "other", _episodes("staf_planned", "line", 0.0))  # another cell: must not count
    faulty = _eval_run(tmp_path, "faulty", _episodes("staf_planned", "wedge", 0.0), [{"kind": "stuck", "robot": 3}])
    [row] = judge_all(gather(list(map(type(tmp_path), [good, other, faulty]))), [claim])
    assert row.verdict == HOLDS and row.measured.ours.value == 100.0 and row.measured.ours.n == 5
    _eval_run(tmp_path, "bad", _episodes("staf_planned", "wedge", 0.9))
    [row] = judge_all(gather([tmp_path / "bad"]), [claim])
    assert row.verdict == PARTLY and row.measured.ours.value == pytest.approx(90.0)
    [row] = judge_all(gather([tmp_path / "other"]), [claim])
    assert row.verdict == MISSING


def test_every_claim_reads_empty_evidence_as_not_measured(tmp_path) -> None:
    rows = judge_all(gather([]))
    assert len(rows) >= 30 and {r.verdict for r in rows} == {MISSING}
    assert {c.paper for c in all_claims()} == {"STAF", "Zhu 2019", "Cezayirli"}


def test_an_unfinished_run_is_refused(tmp_path) -> None:
    run = tmp_path / "half"
    run.mkdir()
    with pytest.raises(StafpipeError, match="not a finished run"):
        gather([run])


def test_an_included_pipeline_keeps_its_own_run_directories(workdir, capsys) -> None:
    (workdir / "pipelines").mkdir()
    (workdir / "pipelines" / "inner.yaml").write_text(
        "name: inner\nsteps:\n  - {name: g, stage: generate, overrides: [experiment=smoke]}\n"
        "  - {name: h, stage: generate, overrides: [experiment=smoke, seed=3, '+note={steps.g.dir}']}\n"
    )
    (workdir / "pipelines" / "outer.yaml").write_text(
        "name: outer\nsteps:\n  - {include: inner}\n"
        "  - {name: report, stage: plot, overrides: [plot.kind=report, 'plot.run_dirs=[{steps.*.dir}]']}\n"
    )
    pipe = load_pipeline(workdir / "pipelines" / "outer.yaml")
    assert [s.name for s in pipe.steps] == ["inner.g", "inner.h", "report"]
    assert pipe.steps[1].overrides[-1] == "+note={steps.inner.g.dir}"
    (workdir / "pipelines" / "loop.yaml").write_text("name: loop\nsteps:\n  - {include: loop}\n")
    with pytest.raises(StafpipeError, match="includes itself"):
        load_pipeline(workdir / "pipelines" / "loop.yaml")


@pytest.mark.slow  # three generate runs and a report, about 6 s
def test_a_report_step_reads_every_earlier_step(workdir, capsys) -> None:
    (workdir / "pipelines").mkdir()
    (workdir / "pipelines" / "inner.yaml").write_text(
        "name: inner\nsteps:\n  - {name: g, stage: generate, overrides: [experiment=smoke]}\n"
    )
    (workdir / "pipelines" / "outer.yaml").write_text(
        "name: outer\nsteps:\n  - {include: inner}\n"
        "  - {name: report, stage: plot, overrides: [plot.kind=report, 'plot.run_dirs=[{steps.*.dir}]']}\n"
    )
    assert run_pipeline("inner") == 0
    capsys.readouterr()
    assert run_pipeline("outer") == 0
    assert "inner.g (generate): skipped" in capsys.readouterr().out
    dirs = job_dirs(workdir)
    assert [d.parent.name for d in dirs] == ["inner", "outer"]
    # generate runs answer no claim: every row is "not measured", none passes or fails by default
    rows = pd.read_csv(dirs[1] / "reproduction.csv")
    assert len(rows) == len(all_claims()) and set(rows.verdict) == {MISSING}
    assert f"{len(rows)} not measured" in (dirs[1] / "REPRODUCTION.md").read_text()
