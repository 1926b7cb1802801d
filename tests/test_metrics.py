import dataclasses
import math

import numpy as np
import pytest

from stafpipe.formations import formation_slots, place
from stafpipe.integrity import circle_integrity, formation_integrity, line_integrity, v_integrity, wedge_shape_integrity
from stafpipe.metrics import (
    MetricContext,
    Trajectory,
    cfi,
    cfi_printed,
    connectivity,
    episode_metrics,
    success_rate,
    travel_time,
    travel_time_of_arrivals,
)


@pytest.mark.parametrize("n", [3, 4, 7, 10])
@pytest.mark.parametrize("kind", ["circle", "wedge", "line", "square", "t", "v"])
def test_perfect_formations_score_one(kind, n) -> None:
    heading = 0.7
    p = place(formation_slots(kind, n, 1.2, 120.0), (3.0, -2.0), heading)
    assert formation_integrity(p, kind, 1.2, heading, 120.0) == pytest.approx(1.0, abs=1e-9)


def test_more_distortion_scores_less() -> None:
    rng = np.random.default_rng(0)
    for kind in ("circle", "wedge", "line", "square"):
        mean = {
            s: np.mean(
                [
                    formation_integrity(formation_slots(kind, 9, 1.0) + rng.normal(0, s, (9, 2)), kind, 1.0, 0.0)
                    for _ in range(50)
                ]
            )
            for s in (0.02, 0.1, 0.3)
        }
        assert 1.0 > mean[0.02] > mean[0.1] > mean[0.3], (kind, mean)


def test_integrity_known_values() -> None:
    # A line with gaps 1 and 3: ideal gap 2, mean deviation 1 -> 1 - 1/2.
    assert line_integrity(np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 4.0]])) == pytest.approx(0.5)
    # A square scored as a circle of 4: every interior angle is the ideal 90 degrees.
    assert circle_integrity(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)) == pytest.approx(1.0)
    # A wedge with one arm twice as long: 1 - 2 |1 - 2| / 3 - |2 L_m - L_b| / L_b.
    apex, lb, rb = np.array([0.0, 0.0]), np.array([-1.0, 1.0]), np.array([-2.0, -2.0])
    l_l, l_r, l_b = math.sqrt(2), math.sqrt(8), math.dist(lb, rb)
    l_m = np.linalg.norm((lb + rb) / 2 - apex)
    expected = 1 - 2 * abs(l_l - l_r) / (l_l + l_r) - abs(2 * l_m - l_b) / l_b
    assert v_integrity(np.stack([apex, lb, rb]), 0.0) == pytest.approx(max(0.0, expected))


@pytest.mark.parametrize("n", [3, 4, 9, 10, 20])
def test_wedge_is_judged_as_a_shape_whichever_way_it_faces(n) -> None:
    rng = np.random.default_rng(n)
    wedge = formation_slots("wedge", n, 1.0)
    for facing in rng.uniform(-math.pi, math.pi, 4):
        p = place(wedge, (1.0, 2.0), facing)
        # the heading passed (a subteam drifting backwards) no longer decides the apex
        assert formation_integrity(p, "wedge", 1.0, facing + math.pi, 90.0) == pytest.approx(
            1.0, abs=1e-6 if n <= 16 else 0.05
        )
        assert v_integrity(p, facing + math.pi) < 0.5  # as judged facing the other way
    # not every shape is a wedge: three in a row, and a wedge with one arm folded in
    assert wedge_shape_integrity(np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 2.0]])) == 0.0
    bent = formation_slots("wedge", 7, 1.0)
    bent[-1] = bent[-3]  # the last robot of one arm stands on its neighbour's place
    assert wedge_shape_integrity(bent + [0.0, 0.01]) < 0.8


def test_cfi_gap_band() -> None:
    eps = np.array([1.0])
    assert cfi(np.array([2.0]), eps, eta=2.0, sigma=0.1) == pytest.approx(1.0)
    assert cfi(np.array([2.15]), eps, eta=2.0, sigma=0.1) == pytest.approx(0.5 * 0.5 + 0.5)
    assert cfi(np.array([3.0]), eps, eta=2.0, sigma=0.1) == pytest.approx(0.5)


def test_cfi_printed_gap_term_as_printed() -> None:
    eps = np.array([1.0])
    # r = diameter / 2; the printed term peaks (1) at r = eta +- sigma and is 0 at r = eta (sigma away from both)
    assert cfi_printed(np.array([2 * 2.1]), eps, eta=2.0, sigma=0.1) == pytest.approx(1.0)
    assert cfi_printed(np.array([2 * 1.9]), eps, eta=2.0, sigma=0.1) == pytest.approx(1.0)
    assert cfi_printed(np.array([2 * 2.0]), eps, eta=2.0, sigma=0.1) == pytest.approx(0.5)
    assert cfi_printed(np.array([2 * 2.05]), eps, eta=2.0, sigma=0.1) == pytest.approx(0.5 * 0.5 + 0.5)
    assert cfi_printed(np.array([2.0]), eps, eta=2.0, sigma=0.1) == pytest.approx(0.5)  # far off: clipped at 0


def test_connectivity_of_a_line_graph() -> None:
    n = 6
    links, lam2 = connectivity(np.stack([np.arange(n) * 1.0, np.zeros(n)], 1)[None], radius=1.5)
    assert links[0] == n - 1
    assert lam2[0] == pytest.approx(2 * (1 - math.cos(math.pi / n)))


def _traj(final_offset: float, collisions=()):
    goal = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    t = np.arange(5) * 0.1
    pos = np.stack([goal + (4 - k) * np.array([1.0, 0.0]) for k in range(5)])
    pos[-1, 2] += final_offset
    z = np.zeros((5, 3))
    return Trajectory(t, pos, np.zeros_like(pos), z.astype(int), goal, z + 1.0, list(collisions))


CTX = MetricContext(0.2, "line", 1.0, 90.0, 0.0, passage_width=3.0, travel_time_lower_bound=0.2)


def test_success_rate_and_travel_time() -> None:
    assert success_rate(_traj(0.0), CTX) == 1.0
    assert travel_time(_traj(0.0), CTX) == pytest.approx(0.4)
    assert success_rate(_traj(1.0), CTX) == pytest.approx(2 / 3)
    assert math.isnan(travel_time(_traj(1.0), CTX))
    goal = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    pos = np.stack([goal + [[0.0, 3 - k], [0.0, 3 - k], [0.0, 5.0]] for k in range(5)]).clip(None, 5.0)
    pos[:, :2, 1] = np.maximum(pos[:, :2, 1], 0.0)  # robots 0 and 1 come down to their slots by 0.3 s; robot 2 never
    two = Trajectory(np.arange(5) * 0.1, pos, np.zeros_like(pos), np.zeros((5, 3), int), goal, np.ones((5, 3)))
    assert math.isnan(travel_time(two, CTX)) and travel_time_of_arrivals(two, CTX) == pytest.approx(0.3)
    assert travel_time_of_arrivals(_traj(0.0), CTX) == travel_time(_traj(0.0), CTX)
    stranded = _traj(0.0)
    stranded.positions[-1] += 5.0
    assert math.isnan(travel_time_of_arrivals(stranded, CTX))
    assert success_rate(_traj(0.0, [(2, 0, 1)]), CTX) == pytest.approx(1 / 3)
    assert success_rate(_traj(0.0, [(2, 2, -1)]), CTX) == pytest.approx(2 / 3)
    m = episode_metrics(_traj(0.0), CTX)
    assert m["tt_ratio"] == pytest.approx(2.0) and m["collisions"] == 0 and m["path_length"] == pytest.approx(4.0)


def test_links_are_sensed_pairs_when_robots_hide_each_other() -> None:
    """Cezayirli Fig. 4 counts sensed neighbours: with occlusion, a robot hidden behind another is no link."""
    row = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]])[None]  # the middle robot hides the outer two from each other
    assert connectivity(row, radius=10.0)[0][0] == 3
    assert connectivity(row, radius=10.0, occlusion_radius=0.5)[0][0] == 2
    apart = np.array([[0.0, 0.0], [2.0, 3.0], [4.0, 0.0]])[None]  # nobody in between
    assert connectivity(apart, radius=10.0, occlusion_radius=0.5)[0][0] == 3


def test_cfi_in_the_passage_counts_only_samples_a_subteam_spends_there() -> None:
    """A 3-robot line walks along x through a passage at x in [4, 6] of a path from (0, 0) to (10, 0): abreast and
    9 m wide before it, a perfect line 2.4 m wide (eta + 0.4: in the sigma-0.5 band) while any robot is inside."""
    line = np.array([[0.0, -1.0], [0.0, 0.0], [0.0, 1.0]])  # 1 m apart across the way: 2r = 2.4 m
    wide = np.array([[0.0, -4.3], [0.0, 0.0], [0.0, 4.3]])  # 9 m wide: gap term 0
    xs = np.arange(0.0, 10.01, 0.5)
    pos = np.stack([(line if 3.5 <= x <= 6.5 else wide) + [x, 0.0] for x in xs])
    z = np.zeros(pos.shape[:2])
    traj = Trajectory(xs, pos, np.zeros_like(pos), z.astype(int), line + [10.0, 0.0], z + 1.0)
    ctx = MetricContext(0.2, "line", 1.0, 90.0, 0.0, passage_width=2.2, travel_time_lower_bound=1.0, cfi_margin=0.1,
                        path=((0.0, 0.0), (10.0, 0.0)), passages=((4.0, 6.0),))  # fmt: skip
    m = episode_metrics(traj, ctx)
    assert m["cfi_passage_0.5"] == pytest.approx(1.0)  # x = 4.0 .. 6.0: five samples, each gap 1 and epsilon 1
    inside = 5 / len(xs)  # the other samples: the wide line (epsilon 1, gap 0) or the line outside (gap 1)
    assert m["cfi_0.5"] == pytest.approx(inside * 1.0 + (2 / len(xs)) * 1.0 + (1 - inside - 2 / len(xs)) * 0.5)
    assert math.isnan(episode_metrics(traj, dataclasses.replace(ctx, passages=()))["cfi_passage_0.5"])


def test_the_corridors_passage_is_where_its_walls_are() -> None:
    from stafpipe.episode import episode_context
    from stafpipe.geometry import Geometry
    from stafpipe.scenario_pool import load_named_scenario
    from stafpipe.sensing import SensingConfig

    corridor = load_named_scenario("corridor")  # walls from x = 12 to 18; the path starts at x = 4
    ctx, _ = episode_context(corridor, Geometry(corridor), SensingConfig(), 0.3, 0.1)
    assert ctx.passages == ((8.0, 14.0),)
