from pathlib import Path

import numpy as np
import pytest

from stafpipe.geometry import Geometry, grid_clearance, obstacle_distance, path_length
from stafpipe.launch import launch
from stafpipe.mapgen import MapsConfig, draw_map
from stafpipe.paths import conf_dir
from stafpipe.scenario import ScenarioError, build_scenario, load_scenario_file
from stafpipe.world import Worlds

DATA = Path(__file__).parent / "data"
BUILT_IN = sorted(p.stem for p in (conf_dir() / "scenario").glob("*.yaml"))


def test_library_holds_the_issue_scenarios() -> None:
    assert set(BUILT_IN) >= {
        "corridor",
        "bridge",
        "doorway",
        "narrowing",
        "multi_passage",
        "bollards",
        "forest",
        "zhu_moving_obstacle",
        "zhu_corridor16",
        "cezayirli_corridors",
    }


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_built_in_scenario_builds_and_steps(name) -> None:
    sc = build_scenario(load_scenario_file(conf_dir() / "scenario" / f"{name}.yaml"))
    worlds = Worlds([sc])
    worlds.reset([0])
    for _ in range(3):
        obs, _ = worlds.step(worlds.goal - worlds.pos)
    assert obs.position.shape == (1, sc.spec.team.n, 2)
    assert (obs.obstacle_distance > -0.05).all()


@pytest.mark.parametrize(
    ("name", "width"),
    [
        ("corridor", 2.4),
        ("bridge", 1.6),
        ("doorway", 1.5),
        ("bollards", 1.1),
        ("narrowing", 2.0),
        ("multi_passage", 3.0),
        ("zhu_corridor16", 2.0),
    ],
)
def test_narrowest_passage_is_derived_from_geometry(name, width) -> None:
    sc = build_scenario(load_scenario_file(conf_dir() / "scenario" / f"{name}.yaml"))
    g = Geometry(sc)
    eta = g.passage_width(tuple(sc.spec.team.start), tuple(sc.spec.team.goal))
    assert eta == pytest.approx(width, abs=2.5 * g.resolution)


@pytest.mark.parametrize("source", ["forest", "office_map", "field", "bollards"])
def test_the_clearance_grid_is_the_distance_to_every_cell_exactly(source) -> None:
    """`grid_clearance` leaves out capsules that cannot be a block's nearest: the grid must still be
    `obstacle_distance` at every cell, to the bit, on a grid that does not split into whole blocks (W, H not
    multiples of 8) and on maps of many obstacles."""
    if source in ("field", "bollards"):
        spec = draw_map(np.random.default_rng(5), MapsConfig(families=[source]), "t")
    else:
        spec = load_scenario_file(conf_dir() / "scenario" / f"{source}.yaml")
    sc = build_scenario(spec)
    w = sc.spec.world
    xs, ys = np.arange(w.xmin + 0.03, w.xmax, 0.0713), np.arange(w.ymin + 0.03, w.ymax, 0.0713)
    assert len(xs) % 8 and len(ys) % 8 and len(sc.capsules) > 8
    cells = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), axis=-1).reshape(-1, 2)
    expected = obstacle_distance(cells, sc).reshape(len(ys), len(xs))
    assert np.array_equal(grid_clearance(xs, ys, sc), expected)
    assert (expected == 0).any() and (expected > 1.0).any()  # inside obstacles and far from them


def test_shortest_path_goes_around_an_obstacle() -> None:
    sc = build_scenario(load_scenario_file(conf_dir() / "scenario" / "zhu_corridor16.yaml"))
    path = Geometry(sc).shortest_path((4.0, 8.0), (36.0, 8.0), 0.2)
    # The 2 m box at (12, 8) blocks the straight line: the path detours, but by less than going over its corner.
    assert 32.0 < path_length(path) < 32.0 + 2 * (2**0.5 - 1) * 1.2 + 0.2


def test_paths_to_one_goal_from_a_tree_rooted_there_are_as_short() -> None:
    """`Geometry.path_to` (one Dijkstra tree rooted at the goal, for L&F's many starts) finds ways as short as a
    search from each start, round the box, and keeps clear of it; no way at all is refused as by `shortest_path`."""
    sc = build_scenario(load_scenario_file(conf_dir() / "scenario" / "zhu_corridor16.yaml"))
    g = Geometry(sc)
    for start in ((4.0, 8.0), (4.3, 7.6), (5.0, 9.1)):
        tree, own = g.path_to(start, (36.0, 8.0), 0.2), g.shortest_path(start, (36.0, 8.0), 0.2)
        assert tree[0] == pytest.approx(start) and tree[-1] == pytest.approx((36.0, 8.0))
        assert path_length(tree) == pytest.approx(path_length(own), abs=2 * g.resolution)
        t = np.linspace(0.0, 1.0, 200)[:, None, None]
        along = (tree[:-1] + t * (tree[1:] - tree[:-1])).reshape(-1, 2)
        assert obstacle_distance(along, sc).min() > 0.2 - 2 * g.resolution  # round the box, clear of it
    with pytest.raises(ValueError, match="no path"):
        g.path_to((4.0, 8.0), (36.0, 8.0), 50.0)


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_issue_example_loads_and_runs_as_written(workdir) -> None:
    code = launch("eval", [f"scenario.path={DATA / 's_example.yaml'}", "eval.episodes=1"])
    assert code == 0
    [results] = list(workdir.glob("outputs/eval/*/*/results.csv"))
    assert "s_example" in results.read_text()


BAD = {
    "team:\n  n: ten\n": "team.n",
    "obstacles:\n  - box: {center: [1, 1], size: [-1, 2]}\n": "obstacles[0].box.size[0]",
    "obstacles:\n  - hexagon: {center: [1, 1]}\n": "obstacles[0]",
    "obstacles:\n  - polygon: [[0, 0], [1, 1]]\n": "obstacles[0].polygon",
    "obstacles:\n  - circle: {center: [1, 1], radius: 1, colour: red}\n": "obstacles[0].circle",
    "robot: {drive: hovercraft}\n": "robot.drive",
    "robot: {radius: -0.2}\n": "robot.radius",
    "team: {start: [99.0, 6.0]}\n": "team.start",
    "team: {formation: blob}\n": "team.formation",
    "time_limit: 0\n": "time_limit",
    "colour: blue\n": "colour",
    "world: {xmin: 5, xmax: 1}\n": "world",
    "obstacles: [\n": "not valid YAML",
}


def complete(text: str) -> str:
    """`text` laid over a minimal valid scenario (a world and a team's start and goal), so each case tests its field."""
    import yaml

    try:
        extra = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    base = {"world": {"xmin": 0, "ymin": 0, "xmax": 30, "ymax": 12}, "team": {"start": [4.0, 6.0], "goal": [26.0, 6.0]}}
    for key, value in extra.items():
        base[key] = {**base[key], **value} if isinstance(value, dict) and isinstance(base.get(key), dict) else value
    return yaml.safe_dump(base)


@pytest.mark.parametrize("text", list(BAD))
def test_malformed_scenario_names_the_field(tmp_path, text) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(complete(text))
    with pytest.raises(ScenarioError) as err:
        build_scenario(load_scenario_file(path))
    assert BAD[text] in str(err.value)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("", "is empty or not a mapping"),
        ("- 1\n- 2\n", "is empty or not a mapping"),
        ("name: x\nteam: {start: [1, 1], goal: [5, 5]}\n", "misses `world`"),
        ("name: x\nworld: {xmin: 0, ymin: 0, xmax: 10, ymax: 10}\n", "misses `team.start`"),
        ("world: {xmin: 0, ymin: 0, xmax: 10, ymax: 10}\nteam: {n: 4, start: [1, 1]}\n", "misses `team.goal`"),
    ],
)
def test_a_scenario_file_takes_nothing_from_the_default_corridor(tmp_path, text, said) -> None:
    path = tmp_path / "part.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=said.replace("`", ".")):
        load_scenario_file(path)


def test_malformed_scenario_through_the_cli_exits_2_and_leaves_nothing(workdir, capsys) -> None:
    bad = workdir / "bad.yaml"
    bad.write_text(complete("robot: {drive: hovercraft}\n"))
    assert launch("eval", [f"scenario.path={bad}"]) == 2
    assert "robot.drive" in capsys.readouterr().err
    assert not list(workdir.rglob("results.parquet")) and not list(workdir.rglob("*.mcap"))


def test_a_failed_run_removes_its_own_empty_folder_and_never_the_folder_the_user_named(workdir) -> None:
    """The run's directory goes (nothing in it but Hydra's files), and Hydra's date folder with it when empty; an
    empty folder the user made and named as the run's parent stays (it may be where they stand)."""
    bad = workdir / "bad.yaml"
    bad.write_text(complete("robot: {drive: hovercraft}\n"))
    mine = workdir / "mine"
    mine.mkdir()
    assert launch("eval", [f"scenario.path={bad}", f"hydra.run.dir={mine / 'run'}"]) == 2
    assert mine.is_dir() and not (mine / "run").exists()
    dated = workdir / "outputs" / "eval" / "2026-12-06"
    assert launch("eval", [f"scenario.path={bad}", f"hydra.run.dir={dated / 'run'}"]) == 2
    assert not dated.exists() and (workdir / "outputs" / "eval").is_dir()


def test_a_folder_of_maps_given_as_the_scenario_is_named_a_folder(tmp_path) -> None:
    (tmp_path / "maps").mkdir()
    with pytest.raises(ScenarioError, match=r"maps is a directory; name one scenario YAML in it"):
        load_scenario_file(tmp_path / "maps")
    with pytest.raises(ScenarioError, match=r"gone.yaml does not exist"):
        load_scenario_file(tmp_path / "gone.yaml")
