import pandas as pd
from typer.testing import CliRunner

from stafpipe.cli import app
from stafpipe.episode import scenario_from_yaml
from stafpipe.episode_log import read_episode
from stafpipe.inspect_log import recompute_metrics
from stafpipe.launch import launch

FAST = ["scenario.time_limit=12", "eval.episodes=2"]


def _eval(*extra):
    assert launch("eval", ["method=straight", "scenario=corridor", *FAST, *extra]) == 0


def test_eval_writes_results_summary_and_episodes(workdir) -> None:
    _eval()
    [run] = [p.parent for p in workdir.glob("outputs/eval/*/*/stage.json")]
    df = pd.read_parquet(run / "results.parquet")
    assert len(df) == 2 and set(df.method) == {"straight"} and (df.tt_lower_bound == 22.0).all()
    summary = pd.read_parquet(run / "summary.parquet").set_index("metric")
    assert summary.loc["sr", "mean"] == df.sr.mean()
    assert len(list((run / "episodes").glob("*.mcap"))) == 2
    for k, path in enumerate(sorted((run / "episodes").glob("*.mcap"))):
        rec = read_episode(path)
        recomputed = recompute_metrics(rec)
        row = df[df.episode == k].iloc[0]
        for key, value in recomputed.items():
            assert value == row[key] or (pd.isna(value) and pd.isna(row[key])), key


def test_same_seed_gives_identical_mcap_messages_and_metrics(workdir) -> None:
    _eval("seed=3")
    _eval("seed=3")
    runs = sorted(p.parent for p in workdir.glob("outputs/eval/*/*/stage.json"))
    a, b = (pd.read_parquet(r / "results.parquet") for r in runs)
    pd.testing.assert_frame_equal(a, b)
    for name in ("episode_0000.mcap", "episode_0001.mcap"):
        assert (runs[0] / "episodes" / name).read_bytes() == (runs[1] / "episodes" / name).read_bytes()


def test_inspect_and_recover(workdir) -> None:
    _eval("eval.episodes=1")
    [path] = list(workdir.glob("outputs/eval/*/*/episodes/*.mcap"))
    runner = CliRunner()
    ok = runner.invoke(app, ["inspect", str(path)])
    assert ok.exit_code == 0 and "equal to the logged ones" in ok.output and "/robots/poses" in ok.output
    cut = workdir / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    bad = runner.invoke(app, ["inspect", str(cut)])
    assert bad.exit_code == 2 and "--recover" in bad.output
    rec = runner.invoke(app, ["inspect", "--recover", str(cut)])
    assert rec.exit_code == 0
    recovered = read_episode(workdir / "cut.recovered.mcap")
    full = read_episode(path)
    k = len(recovered.time)
    assert 0 < k < len(full.time)
    assert (recovered.positions == full.positions[:k]).all()


def test_robot_group_replaces_the_scenario_robot(workdir) -> None:
    _eval("eval.episodes=1", "robot=diff_drive", "robot.max_speed=0.5")
    [path] = list(workdir.glob("outputs/eval/*/*/episodes/*.mcap"))
    robot = scenario_from_yaml(read_episode(path).scenario_yaml).spec.robot
    assert (robot.drive, robot.max_speed, robot.radius) == ("diff_drive", 0.5, 0.2)  # radius kept from corridor.yaml
    assert launch("eval", ["robot.drive=tank", *FAST]) == 2
