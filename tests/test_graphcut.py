"""STAF's deep graph cut: loss terms with known answers, invariances, batching, repair, adaptive m, checkpoints."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stafpipe.errors import StafpipeError
from stafpipe.formations import formation_slots, place
from stafpipe.highlevel.checkpoint import load_checkpoint, save_checkpoint
from stafpipe.highlevel.config import HighLevelConfig
from stafpipe.highlevel.graphs import Team, make_batch, radius_edges
from stafpipe.highlevel.loss import balance_printed, loss_terms
from stafpipe.highlevel.model import DeepGraphCut
from stafpipe.highlevel.partition import (
    balance_sizes,
    balanced_kmeans,
    choose_m,
    formation_width,
    partition_stats,
    repair,
)

CFG = HighLevelConfig()


def two_clusters() -> Team:
    """Robots 0-3 around (0, 0), robots 4-7 around (10, 0); goals 20 m up. Edges only inside a cluster."""
    square = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    pos = np.concatenate([square, square + [10, 0]])
    return Team(pos, pos + [0, 20], 2)


def one_hot(labels, m) -> torch.Tensor:
    return torch.nn.functional.one_hot(torch.tensor(labels), m).float()


def test_loss_terms_known_answers_on_two_clusters() -> None:
    team = two_clusters()
    batch = make_batch([team], CFG.features, 2.0)
    right = loss_terms(one_hot([0] * 4 + [1] * 4, 2), batch)
    assert right["adjacency"].item() == 0.0 and right["balance"].item() == 0.0
    assert right["goal"].item() == pytest.approx(
        1.0
    )  # each half 20 m from its goals, the team 20 m: (4 * 20 + 4 * 20) / (8 * 20)
    mixed = loss_terms(one_hot([0, 1] * 4, 2), batch)
    assert mixed["adjacency"].item() == pytest.approx(8 / 12)  # 12 directed edges per square, 8 cut by alternation
    together = loss_terms(one_hot([0] * 8, 2), batch)
    assert together["adjacency"].item() == 0.0 and together["balance"].item() == pytest.approx(1.0)
    # goals that differ per cluster: cluster 0 moves 20 m, cluster 1 stays; the team centre moves 10 m.
    moved = Team(team.pos, np.concatenate([team.pos[:4] + [0, 20], team.pos[4:]]), 2)
    goal = loss_terms(one_hot([0] * 4 + [1] * 4, 2), make_batch([moved], CFG.features, 2.0))["goal"]
    assert goal.item() == pytest.approx((4 * 20 + 4 * 0) / (8 * 10))
    # an (almost) empty subteam no longer lowers the term: the printed sum over subteams would halve it here
    nearly_empty = loss_terms(torch.tensor([[1.0 - 1e-7, 1e-7]] * 8), make_batch([team], CFG.features, 2.0))["goal"]
    assert nearly_empty.item() == pytest.approx(1.0)


def test_printed_balance_term_is_identically_zero() -> None:
    batch = make_batch([two_clusters()], CFG.features, 2.0)
    y = torch.softmax(torch.randn(8, 2, generator=torch.Generator().manual_seed(0)), dim=1)
    assert abs(balance_printed(y, batch).item()) < 1e-5
    assert loss_terms(y, batch)["balance"].item() > 0  # the used form is not


def _circle_team(n: int, m: int, heading: float = 0.3) -> Team:
    slots = formation_slots("circle", n, 1.0)
    return Team(place(slots, (1.0, 2.0), heading), place(slots, (21.0, 2.0), heading), m)


def test_embedding_and_cut_are_permutation_equivariant() -> None:
    torch.manual_seed(0)
    net = DeepGraphCut(CFG).eval()
    team = _circle_team(9, 3)
    perm = np.random.default_rng(1).permutation(9)
    permuted = Team(team.pos[perm], team.goal[perm], 3)
    with torch.no_grad():
        a, b = (net(make_batch([t], CFG.features, CFG.radius)) for t in (team, permuted))
        ha, hb = (net.embed(make_batch([t], CFG.features, CFG.radius)) for t in (team, permuted))
    assert torch.allclose(a[perm], b, atol=1e-6) and torch.allclose(ha[perm], hb, atol=1e-5)
    assert torch.all(a[:, 3:] == 0) and torch.allclose(a.sum(1), torch.ones(9))  # m = 3 of m_max = 4


def test_a_team_gets_the_same_cut_alone_and_in_a_batch_of_other_sizes() -> None:
    torch.manual_seed(0)
    net = DeepGraphCut(CFG).eval()
    teams = [_circle_team(5, 2), _circle_team(12, 4, 1.0), _circle_team(8, 3, -0.5)]
    with torch.no_grad():
        together = net(make_batch(teams, CFG.features, CFG.radius))
        alone = torch.cat([net(make_batch([t], CFG.features, CFG.radius)) for t in teams])
    assert torch.allclose(together, alone, atol=1e-6)


def test_repair_fills_empty_subteams_and_reconnects_parts() -> None:
    team = two_clusters()
    edges = radius_edges(team.pos, 2.0)
    probs = np.full((8, 3), 1 / 3)
    empty = repair(np.zeros(8, dtype=int), probs, edges, 3)
    assert set(empty) == {0, 1, 2}
    # subteam 0 = robots {0, 1, 4, 5}: two parts 10 m apart; the part in cluster 1 joins subteam 1, its neighbours.
    split = repair(np.array([0, 0, 1, 1, 0, 0, 2, 2]), probs, edges, 3)
    stats = partition_stats(split, team.pos, team.goal, edges, 3)
    assert stats["connected"] == 1.0 and stats["empty_subteams"] == 0.0
    assert len(set(split[:4])) == 2 and len(set(split[4:])) <= 2


def test_balance_sizes_evens_out_a_lopsided_cut_and_keeps_a_balanced_one() -> None:
    line = formation_slots("line", 10, 1.0)  # abreast: y from 4.5 down to -4.5
    lopsided = np.array([0, 0, 0, 1, 2, 2, 2, 3, 3, 3])  # 3-1-3-3, what the shipped cut gives at m = 4
    labels = balance_sizes(lopsided, line, 4)
    assert sorted(np.bincount(labels, minlength=4)) == [2, 2, 3, 3]
    for j in range(4):  # each subteam is a run of neighbours along the line, and keeps its place in it
        members = np.flatnonzero(labels == j)
        assert np.ptp(members) == len(members) - 1
    assert labels[0] == 0 and labels[-1] == 3 and labels[4] in (1, 2)
    even = np.array([0, 0, 0, 1, 1, 1, 2, 2, 3, 3])
    assert (balance_sizes(even, line, 4) == even).all()
    rng = np.random.default_rng(0)
    for m in (3, 4):
        pos, goal = rng.normal(0, 3, (10, 2)), rng.normal(0, 3, (10, 2))
        assert np.ptp(np.bincount(balanced_kmeans(pos, goal, m, 0), minlength=m)) <= 1


def test_adaptive_m_uses_the_formation_width() -> None:
    # 10 robots of radius 0.2 at spacing 0.5 (gap 0.1): circumradius R = 0.5 / (2 sin 18 deg) with a slot on the heading
    # axis, so the widest slots are at +-72 deg: 2 R sin 72 deg + 0.4 = 1.94 m across.
    radius = 0.5 / (2 * np.sin(np.pi / 10))
    assert formation_width("circle", 10, 0.5, 0.2) == pytest.approx(2 * radius * np.sin(np.radians(72)) + 0.4)
    assert choose_m("circle", 10, 2.4, 0.2, 0.1, 4) == (1, True)
    assert choose_m("circle", 10, 2.4, 0.2, 0.3, 4) == (2, True)  # at 0.7 m spacing: 2.55 m wide, 5-robot halves fit
    assert choose_m("line", 9, 2.0, 0.2, 0.3, 4) == (3, True)  # line abreast: 3 robots 1.8 m, 4 robots 2.5 m
    assert choose_m("line", 9, 0.3, 0.2, 0.3, 4) == (4, False)  # nothing fits: the most subteams allowed


def test_checkpoint_round_trip_and_clear_errors(tmp_path) -> None:
    torch.manual_seed(0)
    net = DeepGraphCut(CFG)
    path = save_checkpoint(tmp_path / "a.pt", net, {"note": "test"})
    loaded, made_by = load_checkpoint(path)
    assert made_by == {"note": "test"}
    assert all(torch.equal(a, b) for a, b in zip(net.state_dict().values(), loaded.state_dict().values(), strict=True))
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    torch.save({"format": "other"}, tmp_path / "other.pt")
    bad_shape = torch.load(path, weights_only=True)
    bad_shape["high"]["hidden"] = 16
    torch.save(bad_shape, tmp_path / "shape.pt")
    for name, message in [
        ("missing.pt", "no such checkpoint"),
        ("junk.pt", "not a readable checkpoint"),
        ("other.pt", "not a stafpipe high-level checkpoint"),
        ("shape.pt", "weights do not fit"),
    ]:
        with pytest.raises(StafpipeError, match=message):
            load_checkpoint(tmp_path / name)


def test_numpy_forward_equals_the_torch_network() -> None:
    from stafpipe.highlevel.graphs import team_graph
    from stafpipe.highlevel.model import NumpyGraphCut

    for attention in ("relu", "leaky_relu"):
        torch.manual_seed(3)
        net = DeepGraphCut(HighLevelConfig(attention=attention)).eval()
        fast = NumpyGraphCut(net)
        for team in (
            _circle_team(7, 2),
            _circle_team(12, 4, 2.0),
            Team(np.array([[0.0, 0], [9, 9]]), np.zeros((2, 2)), 1),
        ):
            with torch.no_grad():
                expected = net(make_batch([team], CFG.features, CFG.radius)).numpy()
            g = team_graph(team, CFG.features, CFG.radius)
            assert np.allclose(fast(g.x, g.edges, team.m), expected, atol=1e-5)


@pytest.mark.parametrize("n", [10, 70])  # the search on lists (n <= 64) and scipy
def test_connectivity_of_subteams_on_a_line(n: int) -> None:
    pos = np.stack([np.arange(n, dtype=float), np.zeros(n)], axis=1)
    edges = radius_edges(pos, 1.5)  # each robot sees its two neighbours
    halves = np.repeat([0, 1], n // 2)
    assert partition_stats(halves, pos, pos + 5, edges, 2)["connected"] == 1.0
    sandwich = np.zeros(n, dtype=int)
    sandwich[n // 4 : n // 2] = 1  # robots of subteam 0 on both sides of it
    assert partition_stats(sandwich, pos, pos + 5, edges, 2)["connected"] == 0.0
    fixed = repair(sandwich, np.full((n, 2), 0.5), edges, 2)
    assert partition_stats(fixed, pos, pos + 5, edges, 2)["connected"] == 1.0 and set(fixed) == {0, 1}


def test_the_plans_divider_decides_as_divide_does() -> None:
    """STAF's plan divides a small team on a dense radius graph (highlevel/infer.py, `divider`): the same subteams as
    `divide` on the k-d tree's edge list, for teams of every formation, size and m, some robots out of reach."""
    from stafpipe.highlevel.infer import divide, divider

    model, _ = load_checkpoint("")
    decide = divider()
    rng = np.random.default_rng(5)
    for kind in ("circle", "wedge", "line", "square"):
        for n in (3, 6, 10, 13):
            for m in (2, 3, 4):
                pos = place(formation_slots(kind, n, 1.0), rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi))
                pos = pos + rng.normal(0.0, 0.3, pos.shape)
                pos[0] += 30.0 * (n == 13)  # one robot far beyond the 2 m radius: a node with no neighbour
                goal = pos + rng.uniform(5, 20) * np.array([np.cos(a := rng.uniform(0, 6.3)), np.sin(a)])
                expected = divide(model, [Team(pos, goal, m)])[0]
                assert np.array_equal(decide(pos, goal, m), expected), (kind, n, m)


def test_the_plans_cut_features_are_node_features_to_the_bit() -> None:
    """The plan's split builds the cut's node features itself (highlevel/infer.py, `small_team_features`): the very
    bits of `node_features`, for every feature order the config allows, teams of one robot and goals on the team."""
    from stafpipe.highlevel.graphs import node_features
    from stafpipe.highlevel.infer import small_team_features

    rng = np.random.default_rng(11)
    for k in range(400):
        n = int(rng.integers(1, 16))
        pos = rng.normal(0.0, rng.uniform(0.1, 40.0), (n, 2)) + rng.uniform(-300, 300, 2)
        goal = pos + rng.normal(0.0, 30.0, 2) * (k % 25 != 0)  # some goals on the team: a zero heading
        names = [["pos", "goal", "heading"], ["heading", "pos"], ["goal"], ["pos", "goal", "heading", "vel"]][k % 4]
        team = Team(pos, goal, 2)
        assert np.array_equal(
            small_team_features(team, names).view(np.uint64), node_features(team, names).view(np.uint64)
        )


def _scipy_parts(labels: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Reference: scipy's components of the graph of edges inside subteams."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n, inside = len(labels), labels[edges[0]] == labels[edges[1]]
    graph = coo_matrix((np.ones(inside.sum()), (edges[0][inside], edges[1][inside])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _random_teams(seed: int, sizes: tuple[int, ...], count: int):
    """(labels, edges, m) of random teams, sparse to dense, with scattered or banded subteams."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n = int(rng.choice(sizes))
        m = min(n, int(rng.integers(1, 5)))
        pos = rng.uniform(0, rng.uniform(1.0, 3.0) * np.sqrt(n), (n, 2))
        if rng.random() < 0.5:
            labels = rng.integers(0, m, n)
        else:  # bands across the team: connected where the robots are dense enough
            labels = np.minimum((m * np.argsort(np.argsort(pos[:, 0]))) // n, m - 1)
        yield labels, radius_edges(pos, 2.0), m


def test_subteam_parts_and_connectivity_agree_with_scipy() -> None:
    """`_subteam_parts` searches lists up to 64 robots (ids: each part's lowest robot) and asks scipy beyond: the
    same parts as scipy's components; `connected_subteams` says whole exactly where m parts cover m subteams."""
    from stafpipe.highlevel.partition import _subteam_parts, connected_subteams

    answers = set()
    for labels, edges, m in _random_teams(11, (2, 9, 16, 40, 64, 65, 90), 200):
        parts, reference = _subteam_parts(labels, edges), _scipy_parts(labels, edges)
        pairs = set(zip(parts.tolist(), reference.tolist(), strict=True))  # one part for one component, and back
        assert len(pairs) == len(set(reference.tolist())) == len(set(parts.tolist()))
        if len(labels) <= 64:
            assert all(parts[i] == np.flatnonzero(reference == reference[i]).min() for i in range(len(labels)))
        whole = set(labels.tolist()) == set(range(m)) and len(set(reference.tolist())) == m
        assert connected_subteams(labels, edges, m) == whole
        answers.add(whole)
    assert answers == {True, False}  # both answers were checked


def test_repair_leaves_every_subteam_whole_where_the_graph_is_connected() -> None:
    """Where the radius graph is connected, repair ends with every one of the m subteams non-empty and connected
    (a part cut off from its subteam always touches another one), and leaves a whole partition as it is."""
    from scipy.sparse.csgraph import connected_components

    from stafpipe.highlevel.partition import connected_subteams

    rng = np.random.default_rng(7)
    repaired = 0
    for labels, edges, m in _random_teams(7, (4, 10, 16, 30, 80), 800):
        n = len(labels)
        graph = np.zeros((n, n))
        graph[edges[0], edges[1]] = 1.0
        if connected_components(graph, directed=False)[0] > 1:
            continue
        probs = rng.random((n, 4))
        fixed = repair(labels, probs, edges, m)
        assert connected_subteams(fixed, edges, m)
        if connected_subteams(labels, edges, m):
            assert np.array_equal(fixed, labels)
        repaired += not np.array_equal(fixed, labels)
    assert repaired > 60  # many of them needed a repair
