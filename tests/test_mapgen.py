"""Procedural training maps (stafpipe.mapgen, `stafpipe generate-maps`)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from conftest import job_dirs
from stafpipe.formations import place
from stafpipe.geometry import Geometry, obstacle_distance, path_length
from stafpipe.launch import launch
from stafpipe.mapgen import FAMILIES, MapsConfig, draw_map, generate_maps, turned
from stafpipe.scenario import build_scenario, load_scenario_file


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_every_family_gives_a_passable_map_with_free_start_and_goal(family) -> None:
    spec = draw_map(np.random.default_rng([4, FAMILIES.index(family)]), MapsConfig(families=[family]), "t")
    sc = build_scenario(spec)
    assert spec.name.endswith(family) and len(spec.obstacles) > 0
    t, r = spec.team, spec.robot.radius
    for centre in (t.start, t.goal):  # the team's slots at start and goal are clear of every obstacle
        assert obstacle_distance(place(sc.template(), centre, 0.0), sc).min() > r
    path = Geometry(sc).shortest_path(tuple(t.start), tuple(t.goal), r)
    assert len(path) >= 2 and 4 <= t.n <= 12


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_widths_team_sizes_formations_and_drives_follow_the_config() -> None:
    cfg = MapsConfig(
        count=4,
        families=["corridor", "doorway"],
        width=[1.0, 1.2],
        team_sizes=[5, 6],
        formations=["wedge"],
        drives=["diff_drive"],
    )
    for spec in generate_maps(cfg, seed=2):
        assert spec.team.n in (5, 6) and spec.team.formation == "wedge" and spec.robot.drive == "diff_drive"
        boxes = [o["box"] for o in spec.obstacles]
        lanes = sorted(b["center"][1] - b["size"][1] / 2 for b in boxes if b["center"][1] > spec.world.ymax / 2)
        below = sorted(b["center"][1] + b["size"][1] / 2 for b in boxes if b["center"][1] < spec.world.ymax / 2)
        assert 1.0 - 1e-3 <= lanes[0] - below[-1] <= 1.2 + 1e-3  # the passage's width


@pytest.mark.slow  # over 5 s on 2 cores
def test_maps_depend_only_on_seed_and_index() -> None:
    a = generate_maps(MapsConfig(count=2), seed=7)
    b = generate_maps(MapsConfig(count=1), seed=7)
    c = generate_maps(MapsConfig(count=1), seed=8)
    assert a[:1] == b and a[:1] != c


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_generate_maps_stage_writes_loadable_scenarios_and_refuses_bad_config(workdir) -> None:
    assert launch("generate-maps", ["seed=3", "maps.count=2", "maps.families=[gaps,bollards]"]) == 0
    [run] = job_dirs(workdir)
    index = pd.read_parquet(run / "maps.parquet")
    assert list(index.file) == ["maps/map_0000.yaml", "maps/map_0001.yaml"]
    for row in index.itertuples():
        spec = load_scenario_file(run / row.file)
        assert spec.name == row.name and row.family in ("gaps", "bollards")
    assert launch("generate-maps", ["maps.width=[0.2,1.0]"]) == 2
    assert launch("generate-maps", ["maps.families=[maze]"]) == 2
    assert len(job_dirs(workdir)) == 1


@pytest.mark.slow  # 2-5 s on 2 cores
def test_an_s_bend_whose_pieces_fill_the_stretch_is_drawn() -> None:
    """Seed 11, map 4: the S-bend's three pieces fill the obstacles' stretch exactly, and its start drawn from
    [x0, x1 - 3 seg] had high below low by rounding: the draw raised (high - low < 0) and the map set failed."""
    spec = draw_map(np.random.default_rng([11, 4]), MapsConfig(), "t")
    assert spec.name == "t-s_bend"


@pytest.mark.slow  # about 5 s on 2 cores
def test_turned_maps_travel_other_ways_with_the_same_geometry() -> None:
    """`maps.turns`: a map turned by quarter turns keeps its passage width and shortest way (the world, obstacles,
    team and heading turn together), and with turns on the teams travel more than one way."""
    spec = draw_map(np.random.default_rng([4, 0]), MapsConfig(families=["doorway"]), "t")

    def measured(sc):
        g, t, r = Geometry(sc), sc.spec.team, sc.spec.robot.radius
        way = g.shortest_path(tuple(t.start), tuple(t.goal), r)
        return g.passage_width(tuple(t.start), tuple(t.goal)), path_length(way)

    width, length = measured(build_scenario(spec))
    quarter = np.array([[0.0, -1.0], [1.0, 0.0]])
    for quarters in (1, 2, 3):
        sc = build_scenario(turned(spec, quarters))
        t = sc.spec.team
        expected = np.linalg.matrix_power(quarter, quarters) @ np.subtract(spec.team.goal, spec.team.start)
        assert np.allclose(np.subtract(t.goal, t.start), expected, atol=2e-3) and t.heading_deg == 90.0 * quarters
        w, n = measured(sc)
        assert abs(w - width) < 0.05 and abs(n - length) < 0.1, (quarters, w, width, n, length)
    headings = {m.team.heading_deg for m in generate_maps(MapsConfig(count=6, turns=True), seed=4)}
    assert len(headings) > 1 and headings <= {0.0, 90.0, 180.0, 270.0}
