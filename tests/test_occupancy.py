"""ROS occupancy maps as scenario obstacles: known answers on hand-drawn maps, every bad field refused by name, and
STAF through the shipped office map."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from stafpipe.geometry import obstacle_distance
from stafpipe.occupancy import MapError, load_map
from stafpipe.scenario import ScenarioError, build_scenario, load_scenario_file
from stafpipe.scenario_pool import load_named_scenario

MAP_YAML = "image: {image}\nresolution: {resolution}\norigin: {origin}\nnegate: {negate}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"  # noqa: E501


def draw(tmp_path, cells: np.ndarray, resolution=0.5, origin="[0.0, 0.0, 0.0]", negate=0, suffix=".pgm", **extra):
    """A map whose occupied cells are `cells` (row 0 at the bottom, as in the world), written as ROS draws it:
    occupied black, free white (inverted with negate: 1), image row 0 at the top."""
    img = np.where(cells, 0, 254).astype(np.uint8)[::-1]
    if negate:
        img = 255 - img
    Image.fromarray(img).save(tmp_path / f"m{suffix}")
    text = MAP_YAML.format(image=f"m{suffix}", resolution=resolution, origin=origin, negate=negate)
    text += "".join(f"{k}: {v}\n" for k, v in extra.items())
    (tmp_path / "m.yaml").write_text(text)
    return tmp_path / "m.yaml"


def box_cells() -> np.ndarray:
    cells = np.zeros((8, 12), dtype=bool)
    cells[2:4, 3:7] = True  # x in [1.5, 3.5], y in [1.0, 2.0] at 0.5 m per cell
    return cells


@pytest.mark.parametrize(("negate", "suffix"), [(0, ".pgm"), (1, ".png")])
def test_a_box_of_cells_becomes_its_rectangle(tmp_path, negate, suffix) -> None:
    grid = load_map(draw(tmp_path, box_cells(), negate=negate, suffix=suffix))
    assert grid.extent() == (0.0, 0.0, 6.0, 4.0)
    assert list(grid.contains(np.array([[2.0, 1.5], [1.4, 1.5], [3.6, 1.5], [2.0, 2.1]]))) == [
        True,
        False,
        False,
        False,
    ]
    corners = {p for seg in grid.wall_segments(0.5) for p in seg}
    assert corners == {(1.5, 1.0), (3.5, 1.0), (3.5, 2.0), (1.5, 2.0)}


def test_origin_and_yaw_place_the_map(tmp_path) -> None:
    grid = load_map(draw(tmp_path, box_cells(), origin=f"[10.0, -2.0, {math.pi / 2}]"))
    # the map turned a quarter left about its origin: map (x, y) -> world (10 - y, -2 + x)
    assert list(grid.contains(np.array([[10.0 - 1.5, -2.0 + 2.0], [10.0 + 1.5, -2.0 + 2.0]]))) == [True, False]
    xmin, ymin, xmax, ymax = grid.extent()
    assert np.allclose([xmin, ymin, xmax, ymax], [6.0, -2.0, 10.0, 4.0])


def test_unknown_cells_are_walls_unless_the_scenario_says_free(tmp_path) -> None:
    path = draw(tmp_path, box_cells())
    img = np.asarray(Image.open(tmp_path / "m.pgm")).copy()
    img[0, :] = 205  # the top row: unknown (p = 0.196 .. 0.65)
    Image.fromarray(img).save(tmp_path / "m.pgm")
    top = np.array([[0.25, 3.75]])
    assert load_map(path).contains(top)[0] and not load_map(path, "free").contains(top)[0]


def test_a_scenario_takes_its_walls_and_world_from_the_map(tmp_path) -> None:
    draw(tmp_path, box_cells())
    (tmp_path / "sc.yaml").write_text(
        "name: boxed\noccupancy: {map: m.yaml}\n"
        "team: {n: 2, formation: line, spacing: 0.6, start: [0.8, 3.0], goal: [5.0, 3.0]}\n"
        "robot: {radius: 0.2}\n"
    )
    sc = build_scenario(load_scenario_file(tmp_path / "sc.yaml"))
    w = sc.spec.world
    assert (w.xmin, w.ymin, w.xmax, w.ymax) == (0.0, 0.0, 6.0, 4.0)
    d = obstacle_distance(np.array([[2.5, 1.5], [2.5, 2.5], [0.5, 1.5]]), sc)
    assert np.allclose(d, [0.0, 0.5, 0.5])  # inside the box, 0.5 m above it, 0.5 m from the left wall


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (lambda t: t.replace("image: m.pgm", "image: gone.pgm"), "gone.pgm does not exist"),
        (lambda t: t.replace("image: m.pgm", "image: m.jpg"), "image must name a .pgm or .png"),
        (lambda t: t.replace("resolution: 0.5", "resolution: 0"), "resolution must be a number > 0"),
        (lambda t: t.replace("resolution: 0.5", "resolution: fine"), "resolution must be a number"),
        (lambda t: t.replace("origin: [0.0, 0.0, 0.0]\n", ""), "misses the field 'origin'"),
        (lambda t: t.replace("origin: [0.0, 0.0, 0.0]", "origin: [0.0]"), "origin must be [x, y, yaw]"),
        (lambda t: t.replace("free_thresh: 0.196", "free_thresh: 0.9"), "free_thresh (0.9) must not exceed"),
        (lambda t: t.replace("negate: 0", "negate: 2"), "negate must be 0 or 1"),
        (lambda t: t + "mode: raw\n", "mode must be trinary or scale"),
        (lambda t: "just words", "must be a mapping"),
        (lambda t: "image: [", "not valid YAML"),
    ],
)
def test_a_bad_map_is_refused_naming_the_field(tmp_path, change, named) -> None:
    path = draw(tmp_path, box_cells())
    path.write_text(change(path.read_text()))
    with pytest.raises(MapError, match=named.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        load_map(path)


def test_an_unreadable_image_and_a_missing_map_are_refused(tmp_path) -> None:
    path = draw(tmp_path, box_cells())
    (tmp_path / "m.pgm").write_bytes(b"P5 not really")
    with pytest.raises(MapError, match="cannot be read"):
        load_map(path)
    with pytest.raises(ScenarioError, match=r"occupancy.map: map file .*nowhere.yaml does not exist"):
        (tmp_path / "sc.yaml").write_text("occupancy: {map: nowhere.yaml}\nteam: {start: [1, 1], goal: [2, 2]}\n")
        load_scenario_file(tmp_path / "sc.yaml")


def test_an_image_too_large_is_refused_from_its_header(tmp_path) -> None:
    """A PGM header declaring 20,000 x 20,000 pixels: refused before a pixel is decoded (Pillow would raise its
    DecompressionBombError, or decode 400 million pixels)."""
    path = draw(tmp_path, box_cells())
    (tmp_path / "m.pgm").write_bytes(b"P5\n20000 20000\n255\n" + bytes(16))
    with pytest.raises(MapError, match=r"m.pgm declares more than 50,000,000 pixels"):
        load_map(path)
    (tmp_path / "m.pgm").write_bytes(b"P5\n8000 8000\n255\n" + bytes(16))  # below Pillow's own guard
    with pytest.raises(MapError, match=r"8000 x 8000 pixels, more than 50,000,000"):
        load_map(path)


@pytest.mark.parametrize(
    ("start", "goal", "named"),
    [
        ("[2.5, 1.5]", "[5.0, 3.0]", "team.start .*its centre lies in an occupied cell"),
        ("[0.8, 3.0]", "[2.5, 1.6]", "team.goal .*occupied cell"),
        ("[1.0, 1.5]", "[5.0, 3.0]", "team.start .*robot 1.s slot lies in an occupied cell"),  # slots x 0.3 and 1.7
    ],
)
def test_a_team_starting_or_ending_in_a_wall_is_refused(tmp_path, start, goal, named) -> None:
    draw(tmp_path, box_cells())
    (tmp_path / "sc.yaml").write_text(
        f"occupancy: {{map: m.yaml}}\nteam: {{n: 2, formation: line, spacing: 1.4, "
        f"angle_deg: 90, start: {start}, goal: {goal}, heading_deg: 90}}\n"
        "robot: {radius: 0.2}\n"
    )
    with pytest.raises(ScenarioError, match=named):
        build_scenario(load_scenario_file(tmp_path / "sc.yaml"))


def test_the_shipped_office_map_loads_with_its_doorways_open() -> None:
    sc = load_named_scenario("office_map")
    assert sc.occupancy is not None and 20 < len(sc.capsules) < 200  # walls kept few by the simplification
    doorways = np.array([[10.0, 6.3], [10.0, 2.55]])
    walls = np.array([[10.0, 4.0], [10.0, 8.5], [0.6, 5.0]])
    assert not sc.occupancy.contains(doorways).any() and sc.occupancy.contains(walls).all()
    assert (obstacle_distance(doorways, sc) > 0.4).all()


@pytest.mark.slow  # three STAF episodes, about 15 s
def test_staf_crosses_the_office_map(workdir) -> None:
    import pandas as pd

    from conftest import job_dirs
    from stafpipe.launch import launch

    assert (
        launch("eval", ["method=staf_planned", "scenario=office_map", "eval.episodes=2", "eval.log_episodes=false"])
        == 0
    )
    [run] = job_dirs(workdir)
    results = pd.read_parquet(run / "results.parquet")
    assert (results.sr == 1.0).all() and (results.collisions == 0).all()


def test_a_map_file_keeps_yaml_merge_keys_and_refuses_a_key_written_twice(tmp_path) -> None:
    from stafpipe.occupancy import MapError, load_map

    (tmp_path / "m.pgm").write_bytes(bytes.fromhex("50350a3220320a3235350affffffff"))
    (tmp_path / "ok.yaml").write_text("base: &b {resolution: 0.05, origin: [0, 0, 0]}\n<<: *b\nimage: m.pgm\n")
    assert load_map(tmp_path / "ok.yaml").resolution == 0.05
    (tmp_path / "twice.yaml").write_text("image: m.pgm\nresolution: 1.0\norigin: [0, 0, 0]\nresolution: 0.05\n")
    with pytest.raises(MapError, match="found duplicate key resolution at line 4"):
        load_map(tmp_path / "twice.yaml")
