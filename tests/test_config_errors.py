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
        ("formation=hexagon", "formation/hexagon"),  # unknown group option
        ("data.n_min=1", "data.n_min"),  # out of range
        ("formation.spacing=-1", "formation.spacing"),
    ],
)
def test_bad_config_is_refused(workdir, capsys, override, named) -> None:
    code = launch("generate", ["experiment=smoke", override])
    err = capsys.readouterr().err
    assert code != 0
    assert named in err
    assert _results(workdir) == []
    assert not any(p.name == ".hydra" for p in workdir.rglob("*")), "a failed run left its directory behind"


def test_bad_key_in_a_sweep_runs_no_job(workdir, capsys) -> None:
    code = launch("generate", ["-m", "seed=1,2", "data.nope=3"])
    assert code != 0
    assert "data.nope" in capsys.readouterr().err
    assert _results(workdir) == []
