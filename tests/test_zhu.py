"""Zhu et al. 2019: convex regions, the intersection graph and its spectral partition, merge conditions and consensus,
fault detection on whole episodes, and refused settings."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from stafpipe.controllers.zhu import ZhuController
from stafpipe.controllers.zhu_config import ZhuConfig
from stafpipe.controllers.zhu_decisions import (
    StuckDetector,
    TeamStall,
    comm_components,
    intersection_graph,
    merge_candidate,
    merge_requests,
    mutual_merges,
    needs_split,
    spectral_partition,
    split_team,
)
from stafpipe.convex_region import fit_centres, grow_halfplanes, intersect_all, regions_from_halfplanes
from stafpipe.episode import run_episode
from stafpipe.errors import ConfigError
from stafpipe.faults import Fault
from stafpipe.geometry import Geometry
from stafpipe.scenario import ScenarioConfig, TeamSpec, WorldBounds, build_scenario
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig


def _box(x0: float, y0: float, x1: float, y1: float):
    return np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]), np.array([x1, -x0, y1, -y0])


def test_regions_areas_and_intersections_have_known_values() -> None:
    a, b = regions_from_halfplanes([_box(0, 0, 1, 1), _box(0.5, 0, 1.5, 1)])
    assert a.area == pytest.approx(1.0) and b.area == pytest.approx(1.0)
    (both,) = intersect_all([[a, b]])
    assert both.area == pytest.approx(0.5)
    (none,) = intersect_all([[a, *regions_from_halfplanes([_box(2, 2, 3, 3)])]])
    assert none.empty and none.area == 0.0
    # redundant half-planes are dropped: the region keeps its four edges only
    (r,) = regions_from_halfplanes(
        [(np.concatenate([_box(0, 0, 1, 1)[0], [[1.0, 0.0]]]), np.concatenate([_box(0, 0, 1, 1)[1], [5.0]]))]
    )
    assert len(r.offsets) == 4


def test_grown_region_stays_clear_of_an_obstacle_and_within_sight() -> None:
    # a wall x = 2 (a capsule of radius 0.1) and a robot of radius 0.2 at the origin, visibility 6
    (rows,) = grow_halfplanes(
        np.zeros((1, 2)), np.array([[2.0, -10.0]]), np.array([[2.0, 10.0]]), np.array([0.1]), 6.0, 0.2
    )
    (region,) = regions_from_halfplanes([rows])
    assert region.vertices[:, 0].max() == pytest.approx(2.0 - 0.1 - 0.2)
    assert np.linalg.norm(region.vertices, axis=1).max() <= 6.0 + 1e-9
    assert region.contains(np.zeros((1, 2)))[0]
    # no obstacle: the visibility octagon, 2 sqrt(2) r^2
    (free,) = regions_from_halfplanes(
        grow_halfplanes(np.zeros((1, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), 6.0, 0.2)
    )
    assert free.area == pytest.approx(2 * math.sqrt(2) * 36.0)


def test_formation_fits_nearest_the_target_inside_the_region() -> None:
    (region,) = regions_from_halfplanes([_box(0, 0, 4, 2)])
    hull = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])  # a 1 m square
    inside, too_big = fit_centres(region, [hull, 3 * hull], np.array([2.0, 1.0]))
    assert np.allclose(inside, [2.0, 1.0])
    assert too_big is None
    (clamped,) = fit_centres(region, [hull], np.array([10.0, 5.0]))
    assert np.allclose(clamped, [3.5, 1.5])


def test_spectral_partition_cuts_a_two_cluster_intersection_graph_between_the_clusters() -> None:
    big, small = 30.0, 0.2
    a = np.full((6, 6), small)
    a[:3, :3] = a[3:, 3:] = big
    a[[0, 3, 1], [3, 0, 4]] = a[[3, 0, 4], [0, 3, 1]] = 0.0  # some pairs do not intersect at all
    order = np.array([4, 0, 5, 2, 1, 3])  # shuffle robots so the answer is not the index order
    shuffled = a[np.ix_(order, order)]
    labels = spectral_partition(shuffled, 2)
    groups = {frozenset(order[labels == g].tolist()) for g in (0, 1)}
    assert groups == {frozenset({0, 1, 2}), frozenset({3, 4, 5})}
    assert needs_split(shuffled, 1.0) and not needs_split(a[:3, :3], 1.0)
    parts = split_team(shuffled, {1: 0.0, 2: 1.0, 3: 1.0, 6: 1.0}, max_parts=4)
    assert len(set(parts.tolist())) == 2


def test_intersection_graph_of_regions_on_either_side_of_a_wall() -> None:
    regions = regions_from_halfplanes([_box(0, 0, 2, 2), _box(0, 1, 2, 3), _box(3, 0, 5, 2)])
    a = intersection_graph(regions)
    assert np.allclose(a, [[4, 2, 0], [2, 4, 0], [0, 0, 4]])


def test_merge_conditions_each_required() -> None:
    (common,) = regions_from_halfplanes([_box(0, 0, 3, 3)])
    near, far = np.array([1.0, 1.0]), np.array([5.0, 1.0])
    assert merge_candidate(near, np.array([2.0, 2.0]), common, p_max=3.0, v_min=8.0, in_range=True)
    assert not merge_candidate(near, far, common, p_max=3.0, v_min=8.0, in_range=True)  # centres too far
    assert not merge_candidate(near, np.array([2.0, 2.0]), common, p_max=3.0, v_min=10.0, in_range=True)  # too small
    assert not merge_candidate(near, np.array([2.0, 2.0]), common, p_max=3.0, v_min=8.0, in_range=False)  # silent


def test_merge_consensus_takes_the_largest_common_region_and_needs_both_sides() -> None:
    # teams 1 = {0, 1}, 2 = {2}, 3 = {3}; robot 0 hears team 2, robot 1 hears team 3; robots 0 and 1 talk
    teams = {1: [0, 1], 2: [2], 3: [3]}
    comm = np.zeros((4, 4), dtype=bool)
    for i, j in [(0, 1), (0, 2), (1, 3)]:
        comm[i, j] = comm[j, i] = True
    candidates = {(1, 2): 5.0, (2, 1): 5.0, (1, 3): 9.0, (3, 1): 9.0}
    requests = merge_requests(teams, comm, candidates)
    assert requests == {1: 3, 2: 1, 3: 1}  # robot 0 starts with team 2, adopts robot 1's larger choice (team 3)
    assert mutual_merges(requests) == [(1, 3)]


def test_flooding_reaches_only_the_connected_part_of_a_team() -> None:
    comm = np.ones((4, 4), dtype=bool)
    comm[2, :] = comm[:, 2] = False  # robot 2 is silent
    assert comm_components(comm, [0, 1, 2, 3]) == [[0, 1, 3], [2]]


def test_stuck_detector_flags_only_a_robot_that_makes_no_progress() -> None:
    det = StuckDetector(3, n_dead=5, dp_min=0.1, near=0.3)
    target = np.array([[10.0, 0.0], [10.0, 1.0], [0.0, 2.0]])  # robot 2 sits at its target
    p = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 2.0]])
    flags = []
    for _ in range(8):
        p = p + np.array([[0.1, 0.0], [0.0, 0.0], [0.0, 0.0]])
        flags.append(det.update(p, target))
    assert not np.any([f[0] for f in flags]) and not np.any([f[2] for f in flags])
    assert flags[-1][1] and not flags[3][1]  # flagged once it has had n_dead steps of no progress


def _open_lane(n: int = 4) -> ScenarioConfig:
    return ScenarioConfig(
        name="lane",
        world=WorldBounds(0, -6, 40, 6),
        obstacles=[],
        team=TeamSpec(n=n, formation="square", spacing=1.0, start=(3.0, 0.0), goal=(30.0, 0.0), heading_deg=0.0),
        time_limit=60.0,
    )


def _events(faults: list[Fault]) -> tuple[list[tuple[str, list[int]]], dict[str, float]]:
    """Run an open-lane episode with `faults` injected by the world; the events Zhu's method decided (without the
    region snapshots) and its metrics."""
    scenario = build_scenario(_open_lane())
    controller = ZhuController(ZhuConfig())
    world = WorldConfig(faults=faults)
    values = run_episode(
        scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, world, SensingConfig(radius=3.0)
    )
    return [(e.kind, e.robots) for e in controller.world_view(0).drain_events() if e.kind != "regions"], values


def test_a_stuck_robot_is_flagged_exactly_left_behind_and_merges_back_after_recovering() -> None:
    kinds, values = _events([Fault(robot=1, kind="stuck", start=3.0, end=8.0)])
    assert ("stuck", [1]) in kinds
    assert all(r == [1] for k, r in kinds if k == "stuck")  # nobody else is flagged
    assert ("merge", [0, 1, 2, 3]) in kinds[kinds.index(("stuck", [1])) :]  # it rejoins after the fault
    assert values["sr"] == 1.0


def test_a_silent_robot_is_dropped_and_rejoins_when_it_talks_again() -> None:
    kinds, values = _events([Fault(robot=2, kind="silent", start=3.0, end=8.0)])
    assert ("comm_loss", [2]) in kinds
    assert all(r == [2] for k, r in kinds if k == "comm_loss")
    assert ("merge", [0, 1, 2, 3]) in kinds[kinds.index(("comm_loss", [2])) :]
    assert values["sr"] == 1.0


def test_teams_still_apart_at_the_goal_take_their_robots_goal_slots() -> None:
    # Scenario 1's loop (its walker left out) with robot 2 silent from 8 s to the end: it is dropped and never merges
    # back, so two teams come home apart. With home_slots each heads for the goal slots one assignment of all robots
    # gives its members, and every robot is home; without it the three fitted their own square round the goal
    # centre, on no goal slot (SR 0, as until 2026-12-06)
    spec = dataclasses.replace(load_named_scenario("zhu_moving_obstacle").spec, moving_obstacles=[])
    scenario = build_scenario(spec)
    world = WorldConfig(faults=[Fault(robot=2, kind="silent", start=8.0, end=None)])
    sr = {}
    for home_slots in (False, True):
        controller = ZhuController(ZhuConfig(home_slots=home_slots))
        values = run_episode(
            scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, world, SensingConfig(radius=3.0)
        )
        kinds = [(e.kind, e.robots) for e in controller.world_view(0).drain_events() if e.kind != "regions"]
        assert ("comm_loss", [2]) in kinds and ("merge", [0, 1, 2, 3]) not in kinds
        assert values["collisions"] == 0
        sr[home_slots] = values["sr"]
    assert sr == {False: 0.0, True: 1.0}


def test_a_corridor_too_narrow_for_the_square_splits_the_team_and_it_merges_after() -> None:
    # two walls leave a 1.6 m gap at x in [14, 18]: the 1 m square (1.4 m wide with its radius) fits only with 0.1 m
    # to spare on each side, which the regions grown at the corners do not leave
    spec = dataclasses.replace(
        _open_lane(),
        obstacles=[
            {"box": {"center": [16.0, 3.8], "size": [4.0, 6.0]}},
            {"box": {"center": [16.0, -3.8], "size": [4.0, 6.0]}},
        ],
    )
    scenario = build_scenario(spec)
    controller = ZhuController(ZhuConfig())
    values = run_episode(
        scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, WorldConfig(), SensingConfig(radius=3.0)
    )
    kinds = [e.kind for e in controller.world_view(0).drain_events()]
    assert "split" in kinds and "merge" in kinds[kinds.index("split") :]
    assert values["obstacle_collisions"] == 0
    assert values["sr"] == 1.0
    assert "regions" in kinds  # the common regions are logged for the snapshots plot


def test_team_stall_needs_the_whole_window_far_from_p_r_without_moving() -> None:
    stall, far, near = TeamStall(window=3.0, dp_min=0.15), 3.0, 1.0
    team, single = (0, 1), (2,)
    still = np.array([5.0, 0.0])
    for t in range(3):
        assert stall.update(float(t), {team: (still, far), single: (still, far)}, max_lag=2.5) == []
    assert stall.update(3.0, {team: (still + 0.1, far), single: (still, far)}, max_lag=2.5) == [team]  # not one robot
    assert stall.update(4.0, {team: (still + 0.2, far)}, max_lag=2.5) == []  # moved 0.2 m: a new window
    assert stall.update(7.0, {team: (still + 0.2, near)}, max_lag=2.5) == []  # within max_lag of p_r: never
    assert stall.update(9.9, {team: (still + 0.2, far)}, max_lag=2.5) == []
    assert stall.update(10.0, {team: (still + 0.2, far)}, max_lag=2.5) == [team]
    assert stall.update(11.0, {(0, 1, 2): (still, far)}, max_lag=2.5) == []  # other members: a new team, a new window


def test_a_line_stalled_at_a_door_its_regions_do_not_reach_splits_and_passes() -> None:
    # three robots abreast (2.4 m) meet a 1.5 m door in a 2 m thick wall: the outer two robots' regions end at the
    # wall, so the common region does too, no pair of regions fails the split check, and before TeamStall the team
    # waited at the wall for the whole episode (SR 0, no contacts)
    spec = dataclasses.replace(
        _open_lane(3),
        team=TeamSpec(n=3, formation="line", spacing=1.0, start=(4.0, 0.25), goal=(22.0, 0.25), heading_deg=0.0),
        obstacles=[
            {"box": {"center": [12.0, -3.25], "size": [2.0, 5.5]}},
            {"box": {"center": [12.0, 3.5], "size": [2.0, 5.0]}},
        ],
        world=WorldBounds(0, -6, 26, 6),
    )
    scenario = build_scenario(spec)
    sr = {}
    for stall_time in (0.0, 3.0):
        controller = ZhuController(dataclasses.replace(ZhuConfig(), stall_time=stall_time))
        values = run_episode(
            scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, WorldConfig(), SensingConfig()
        )
        events = [e for e in controller.world_view(0).drain_events() if e.kind == "split"]
        sr[stall_time] = values["sr"]
        assert values["collisions"] == 0
        assert all("stalled" in e.detail for e in events) and bool(events) == (stall_time > 0)
    assert sr == {0.0: 0.0, 3.0: 1.0}


def test_a_robot_left_behind_a_narrow_door_follows_the_path_to_it() -> None:
    # four robots in a line before a 0.66 m door (a generated map no study had seen): one slips through and p_r goes
    # on with it; the others, aiming at p_r beyond the wall, stood at the wall's face nearest it for the rest of the
    # episode (SR 0; 0.25 since the one through takes its goal slot, `home_slots`). Aiming 1 m ahead of their own
    # place on the path (`team_reference`) brings them to the door.
    spec = dataclasses.replace(
        _open_lane(4),
        team=TeamSpec(n=4, formation="line", spacing=1.0, start=(1.5, 5.565), goal=(16.41, 6.389), heading_deg=0.0),
        obstacles=[
            {"box": {"center": [9.264, 1.418], "size": [0.394, 2.835]}},
            {"box": {"center": [9.264, 7.314], "size": [0.394, 7.633]}},
        ],
        world=WorldBounds(0, 0, 17.91, 11.13),
        time_limit=60.0,
    )
    scenario = build_scenario(spec)
    sr = {}
    for team_reference in (False, True):
        controller = ZhuController(dataclasses.replace(ZhuConfig(), team_reference=team_reference))
        values = run_episode(
            scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, WorldConfig(), SensingConfig()
        )
        sr[team_reference] = values["sr"]
        assert values["collisions"] == 0
    assert sr == {False: 0.25, True: 1.0}


def test_a_team_spaced_tighter_than_the_shrink_floor_keeps_its_spacing() -> None:
    # spacing 0.4 m = the robots' diameter: below 2 r + 0.1 m no scale of the template is allowed, and the fit had
    # no candidate at all (a crash); now the template keeps its own spacing
    spec = dataclasses.replace(_open_lane(), team=dataclasses.replace(_open_lane().team, spacing=0.4))
    scenario = build_scenario(spec)
    values = run_episode(
        scenario,
        Geometry(scenario, resolution=0.1),
        ZhuController(ZhuConfig()),
        "zhu",
        0,
        WorldConfig(),
        SensingConfig(),
    )
    assert values["sr"] == 1.0


def test_the_whole_team_at_its_goal_takes_its_goal_slots_without_splitting_again() -> None:
    # a circle of 20 whose goal is 5 m from the world's edge: there the robots' regions overlap less than the
    # circle's V_min, so the split check split the team once it was home and it never took its goal slots (SR 0)
    spec = ScenarioConfig(
        name="edge",
        world=WorldBounds(0, 0, 24, 16),
        obstacles=[],
        team=TeamSpec(n=20, formation="circle", spacing=1.0, start=(5.0, 8.0), goal=(19.0, 8.0), heading_deg=0.0),
        time_limit=60.0,
    )
    scenario = build_scenario(spec)
    controller = ZhuController(ZhuConfig())
    values = run_episode(
        scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, WorldConfig(), SensingConfig()
    )
    kinds = [e.kind for e in controller.world_view(0).drain_events() if e.kind != "regions"]
    assert values["sr"] == 1.0
    assert kinds[-1] == "merge"  # split on the way (the team is wider than its regions' overlap), merged, home


def test_timings_per_part_are_reported() -> None:
    scenario = build_scenario(_open_lane())
    controller = ZhuController(ZhuConfig())
    run_episode(
        scenario, Geometry(scenario, resolution=0.1), controller, "zhu", 0, WorldConfig(), SensingConfig(radius=3.0)
    )
    stats = controller.world_view(0).episode_stats()
    assert stats["time_convex_regions_count"] > 10 and stats["time_convex_regions_mean"] > 0
    assert stats["time_convex_regions_min"] <= stats["time_convex_regions_mean"] <= stats["time_convex_regions_max"]
    assert math.isnan(stats["time_graph_partition_mean"])  # no split in an open lane
    json.dumps(stats)


@pytest.mark.parametrize(
    ("field", "value", "needle"),
    [
        ("visibility", -1.0, "visibility"),
        ("v_min", 500.0, "larger than any region"),
        ("p_max", 0.0, "p_max"),
        ("scales", [1.5], "scales"),
        ("stall_time", -1.0, "stall_time"),
    ],
)
def test_bad_settings_are_refused_with_the_key(field: str, value: object, needle: str) -> None:
    with pytest.raises(ConfigError, match=needle.replace("[", r"\[").replace("]", r"\]")):
        ZhuController(dataclasses.replace(ZhuConfig(), **{field: value}))


def test_a_fault_on_a_robot_that_does_not_exist_is_refused() -> None:
    from stafpipe.world import Worlds

    with pytest.raises(ConfigError, match=r"world.faults\[0\].robot"):
        Worlds([build_scenario(_open_lane())], SensingConfig(), WorldConfig(faults=[Fault(robot=7)]))
