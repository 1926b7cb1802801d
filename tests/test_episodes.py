import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from stafpipe.cli import app
from stafpipe.episode import scenario_from_yaml
from stafpipe.episode_log import read_episode, recover
from stafpipe.inspect_log import recompute_metrics
from stafpipe.launch import launch
from stafpipe.mcap_check import check, intact_records

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


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
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
    assert bad.exit_code == 2 and "--recover" in bad.output and "truncated" in bad.output
    rec = runner.invoke(app, ["inspect", "--recover", str(cut)])
    assert rec.exit_code == 0
    recovered = read_episode(workdir / "cut.recovered.mcap")
    full = read_episode(path)
    k = len(recovered.time)
    assert 0 < k < len(full.time) and recovered.recovered is not None
    assert (recovered.positions == full.positions[:k]).all()
    shown = runner.invoke(app, ["inspect", str(workdir / "cut.recovered.mcap")])
    assert shown.exit_code == 0 and "PARTIAL" in shown.output


def test_a_flipped_byte_anywhere_is_found(workdir) -> None:
    _eval("eval.episodes=1")
    [path] = list(workdir.glob("outputs/eval/*/*/episodes/*.mcap"))
    data = path.read_bytes()
    assert check(data) == []
    rng = np.random.default_rng(0)
    # the head and tail records byte by byte (magic, Header, DataEnd, summary, Footer), the rest sampled
    spots = [*range(80), *range(len(data) - 700, len(data)), *rng.integers(80, len(data) - 700, 150)]
    for q in spots:
        flipped = bytearray(data)
        flipped[q] ^= 1 << int(rng.integers(8))
        assert check(bytes(flipped)), q


def _chunk_offsets(data: bytes) -> list[int]:
    pos, out = 8, []
    while data[pos] != 0x0F:  # DataEnd
        if data[pos] == 0x06:
            out.append(pos)
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    return out


def test_recover_keeps_every_intact_chunk_after_a_damaged_one(workdir) -> None:
    _eval("eval.episodes=1")
    [path] = list(workdir.glob("outputs/eval/*/*/episodes/*.mcap"))
    data = path.read_bytes()
    whole = intact_records(data)
    assert whole.chunks >= 3 and not whole.damaged
    second = _chunk_offsets(data)[1]  # the first chunk holds /episode, without which nothing is an episode
    damaged = bytearray(data)
    damaged[second + 100] ^= 0xFF
    damaged_path = workdir / "flip.mcap"
    damaged_path.write_bytes(bytes(damaged))
    bad = CliRunner().invoke(app, ["inspect", str(damaged_path)])
    assert bad.exit_code == 2 and "chunk fails its CRC" in bad.output
    kept, _, damage = recover(damaged_path, workdir / "flip.recovered.mcap")
    scan = intact_records(bytes(damaged))
    assert scan.chunks == whole.chunks - 1 and kept == len(scan.messages) > 0.5 * len(whole.messages)
    assert next(str(d) for d in damage).startswith("byte")
    full, part = read_episode(path), read_episode(workdir / "flip.recovered.mcap")
    assert part.time[-1] == full.time[-1] and 0 < len(part.time) < len(full.time)  # the end is kept


def test_robot_group_replaces_the_scenario_robot(workdir) -> None:
    _eval("eval.episodes=1", "robot=diff_drive", "robot.max_speed=0.5")
    [path] = list(workdir.glob("outputs/eval/*/*/episodes/*.mcap"))
    robot = scenario_from_yaml(read_episode(path).scenario_yaml).spec.robot
    assert (robot.drive, robot.max_speed, robot.radius) == ("diff_drive", 0.5, 0.2)  # radius kept from corridor.yaml
    assert launch("eval", ["robot.drive=tank", *FAST]) == 2


def test_a_team_is_stuck_only_after_standing_still_for_the_whole_stretch() -> None:
    from stafpipe.episode import Standstill

    pos = np.zeros((2, 3, 2))  # two worlds of three robots
    still = Standstill(pos, stuck_time=0.3, dt=0.1)
    assert not still.update(pos).any() and not still.update(pos).any()
    pos[1, 2] = [0.11, 0.0]  # world 1: one robot moves further than STUCK_DISTANCE: a new stretch begins
    assert still.update(pos).tolist() == [True, False]
    pos[1, 2] = [0.15, 0.0]  # within 0.1 m of where the new stretch began: standing still
    assert still.update(pos).tolist() == [True, False]
    assert still.update(pos).tolist() == [True, False] and still.update(pos).tolist() == [True, True]
    assert not Standstill(pos, stuck_time=0.0, dt=0.1).update(pos).any()  # 0: off


def test_inspect_outlines_a_log_too_long_to_recompute_and_says_so(workdir, monkeypatch) -> None:
    """Above `MAX_RECOMPUTED` robot-steps inspect checks and outlines the log without holding its states, and says
    plainly that the metrics were not recomputed; below it, the same outline and the metrics."""
    import stafpipe.inspect_log as inspect_log

    out = workdir / "run"
    words = ["eval", "method=straight", "scenario=corridor", "eval.episodes=1", "scenario.time_limit=3"]
    assert CliRunner().invoke(app, [*words, f"hydra.run.dir={out}"]).exit_code == 0
    log = str(out / "episodes" / "episode_0000.mcap")
    full, equal = inspect_log.describe(log)
    assert equal and "equal to the logged ones" in full
    monkeypatch.setattr(inspect_log, "MAX_RECOMPUTED", 100)  # 31 steps x 10 robots is above it
    outline, equal = inspect_log.describe(log)
    assert "metrics NOT recomputed: 310 robot-steps" in outline and "sr " not in outline
    assert outline.splitlines()[:5] == full.splitlines()[:5]  # the same outline either way


def test_recover_on_an_intact_log_writes_nothing(workdir) -> None:
    out = workdir / "run"
    words = ["eval", "method=straight", "scenario=corridor", "eval.episodes=1", "scenario.time_limit=2"]
    assert CliRunner().invoke(app, [*words, f"hydra.run.dir={out}"]).exit_code == 0
    log = out / "episodes" / "episode_0000.mcap"
    result = CliRunner().invoke(app, ["inspect", "--recover", str(log)])
    assert result.exit_code == 0 and "no damage found; nothing to recover, nothing written" in result.output
    assert not list(log.parent.glob("*.recovered.mcap"))


def test_a_file_view_reads_what_the_bytes_hold(tmp_path, monkeypatch) -> None:
    """`FileView` (the scan's bounded-memory reader) answers every index, slice and search as the file's bytes do,
    across block edges (blocks made small here), and `check` finds the same damage either way."""
    import random

    import stafpipe.mcap_check as mc

    monkeypatch.setattr(mc, "BLOCK", 64)
    rng = random.Random(1)
    data = bytes(rng.randrange(256) for _ in range(5000))
    path = tmp_path / "f.bin"
    path.write_bytes(data)
    with open(path, "rb") as f:
        view = mc.FileView(f)
        for _ in range(2000):
            a, b = rng.randrange(-len(data), len(data)), rng.randrange(len(data) + 10)
            sub = bytes([rng.randrange(256)]) * rng.choice([1, 2])
            start = rng.randrange(len(data))
            assert view[a] == data[a] and view[a:b] == data[a:b] and view.find(sub, start) == data.find(sub, start)
        assert mc.crc_of(view, 3, len(data) - 7) == mc.crc_of(data, 3, len(data) - 7)
        assert [str(d) for d in check(view)] == [str(d) for d in check(data)]
