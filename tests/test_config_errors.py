"""A bad config fails before any work, names the key, exits non-zero, and leaves no results."""

import pytest

from stafpipe.launch import launch


def _results(root):
    return list(root.rglob("*.parquet")) + list(root.rglob("stage.json"))


@pytest.mark.parametrize(
    ("override", "named"),
    [
        ("datta.instances=5", "datta"),  # unknown key
        ("data.instances=many", "data.instances"),  # wrong type
        ("formation=hexagon", "formation=hexagon: no such formation; choose one of: circle, line"),  # group option
        ("data.n_min=1", "data.n_min"),  # out of range
        ("formation.spacing=-1", "formation.spacing"),
    ],
)
def test_bad_config_is_refused(workdir, capsys, override, named) -> None:
    code = launch("generate", ["experiment=smoke", override])
    err = capsys.readouterr().err
    assert code == 2  # every user error exits 2 (docs/decisions.md)
    assert named in err and "base_" not in err and "search path" not in err
    assert _results(workdir) == []
    assert not any(p.name == ".hydra" for p in workdir.rglob("*")), "a failed run left its directory behind"


def test_bad_key_in_a_sweep_runs_no_job(workdir, capsys) -> None:
    code = launch("generate", ["-m", "seed=1,2", "data.nope=3"])
    assert code == 2
    assert "data.nope" in capsys.readouterr().err
    assert _results(workdir) == []


@pytest.mark.parametrize(
    ("overrides", "said"),
    [
        (["eval.episode=3"], "eval.episode is not a setting of `stafpipe eval` (did you mean eval.episodes?)"),
        (["evl.episodes=3"], "(did you mean eval?)"),
        (
            ["method=staf_planed"],
            "method=staf_planed: no such method (did you mean method=staf_planned?); "
            "choose one of: cezayirli, dgnn, lf",
        ),
        (["-m", "method=straight,stf"], "method=stf: no such method"),  # a bad value anywhere in a sweep: no job runs
        (["robot=diffdrive"], "did you mean robot=diff_drive?"),
        (["scenario.team.n=many"], "scenario.team.n: Value 'many'"),
    ],
)
def test_config_errors_are_said_in_the_users_terms(workdir, capsys, overrides, said) -> None:
    code = launch("eval", ["eval.episodes=1", *overrides])
    err = capsys.readouterr().err
    assert code == 2 and said in err and "HYDRA_FULL_ERROR" not in err and "base_" not in err, err
    assert _results(workdir) == []


@pytest.mark.parametrize(
    ("override", "named"),
    [
        ("+eval.episode=3", "eval.episodes?"),  # appended misspelling: refused with the right name, not dropped
        ("eval.goal_tolerance=inf", "eval.goal_tolerance"),  # would give SR 1.0
        ("world.start_noise=nan", "world.start_noise"),
        ("world.control_dt=-1", "world.control_dt"),  # would record a 0-step episode as finished
        ("world.substeps=0", "world.substeps"),
        ("world.collision_slop=-1", "world.collision_slop"),
        ("sensing.radius=0", "sensing.radius"),
        ("sensing.drop_prob=2", "sensing.drop_prob"),
        ("sensing.range_error=-0.1", "sensing.range_error"),
        ("seed=-1", "seed"),
    ],
)
def test_every_stage_checks_the_shared_sections(workdir, capsys, override, named) -> None:
    code = launch("eval", ["method=straight", "eval.episodes=1", "scenario.time_limit=2", override])
    err = capsys.readouterr().err
    assert code == 2 and named in err, err
    assert _results(workdir) == []
    assert not any(p.name == ".hydra" for p in workdir.rglob("*")), "a failed run left its directory behind"
