import math

import numpy as np
import pytest
from scipy.spatial.distance import pdist, squareform

from stafpipe.formations import FORMATION_TYPES, assign_slots, formation_slots, place


@pytest.mark.parametrize("kind", FORMATION_TYPES)
@pytest.mark.parametrize("n", [2, 3, 4, 7, 10, 16])
def test_slots_centred_distinct_and_spaced(kind, n) -> None:
    slots = formation_slots(kind, n, 1.5)
    assert slots.shape == (n, 2)
    assert np.allclose(slots.mean(axis=0), 0.0)
    d = squareform(pdist(slots))
    np.fill_diagonal(d, np.inf)
    # Every robot's nearest neighbour is at the spacing or further (none closer: no overlap by construction).
    assert d.min() >= 1.5 * math.sin(math.radians(45)) - 1e-9


def test_circle_neighbours_are_one_spacing_apart() -> None:
    slots = formation_slots("circle", 10, 1.0)
    gaps = np.linalg.norm(slots - np.roll(slots, 1, axis=0), axis=1)
    assert np.allclose(gaps, 1.0)
    assert np.allclose(np.linalg.norm(slots, axis=1), 1.0 / (2 * math.sin(math.pi / 10)))


def test_line_is_abreast_and_wedge_has_right_apex() -> None:
    line = formation_slots("line", 5, 1.0)
    assert np.allclose(line[:, 0], 0.0) and np.isclose(np.ptp(line[:, 1]), 4.0)
    wedge = formation_slots("wedge", 7, 1.0)
    apex, left, right = wedge[0], wedge[-2], wedge[-1]
    u, v = left - apex, right - apex
    assert math.degrees(math.acos(u @ v / np.linalg.norm(u) / np.linalg.norm(v))) == pytest.approx(90.0)
    assert apex[0] == wedge[:, 0].max(), "the wedge points where the formation heads (+x)"


def test_square_of_sixteen_is_four_by_four() -> None:
    slots = formation_slots("square", 16, 1.0)
    assert len(np.unique(slots[:, 0].round(9))) == 4 and len(np.unique(slots[:, 1].round(9))) == 4


def test_place_rotates_heading() -> None:
    line = formation_slots("line", 3, 1.0)
    placed = place(line, (5.0, 1.0), math.pi / 2)  # heading +y: the line lies along x
    assert np.allclose(placed[:, 1], 1.0)
    assert np.allclose(sorted(placed[:, 0]), [4.0, 5.0, 6.0])


def test_hungarian_assignment_recovers_a_permutation() -> None:
    rng = np.random.default_rng(0)
    slots = formation_slots("circle", 9, 2.0)
    perm = rng.permutation(9)
    robots = slots[perm] + rng.normal(0, 0.05, size=(9, 2))
    assert np.array_equal(assign_slots(robots, slots), perm)


def test_bad_formation_arguments() -> None:
    with pytest.raises(ValueError, match="unknown formation"):
        formation_slots("hexagon", 4, 1.0)
    with pytest.raises(ValueError, match="at least 2"):
        formation_slots("circle", 1, 1.0)
    with pytest.raises(ValueError, match="spacing"):
        formation_slots("line", 3, 0.0)


def test_assignment_costs_are_cdists_to_the_bit() -> None:
    """assign_slots sums dx^2 + dy^2 itself (the split's time budget): the same robot-to-slot choice as scipy's
    "sqeuclidean" cdist gives to the Hungarian method, for spread-out, crowded and tied teams."""
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(3)
    for k in range(300):
        n = int(rng.integers(1, 14))
        robots = rng.normal(0.0, rng.uniform(0.01, 50.0), (n, 2)) + rng.uniform(-500, 500, 2)
        slots = robots[rng.permutation(n)] + rng.normal(0.0, rng.uniform(0.0, 3.0), (n, 2)) * (k % 10 != 0)
        rows, cols = linear_sum_assignment(cdist(robots, slots, "sqeuclidean"))
        expected = np.empty(n, dtype=int)
        expected[rows] = cols
        assert np.array_equal(assign_slots(robots, slots), expected)
