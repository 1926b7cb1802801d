"""The decisions of Zhu, Juhl, Ferranti, Alonso-Mora (ICRA 2019) as plain functions: the intersection graph and split
check (Algorithm 1), spectral partition ([21]), the merge conditions and consensus (Section IV-C, Algorithm 2), and
fault detection (Section IV-D). `controllers/zhu.py` calls them; tests call them with hand-built inputs.
"""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy.cluster.vq import kmeans, vq
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from stafpipe.convex_region import Region, intersection_areas


def intersection_graph(regions: list[Region]) -> np.ndarray:
    """Algorithm 1, steps 6-7: A_a(i, j) = V(P_i ∩ P_j), symmetric (m, m); the diagonal holds V(P_i)."""
    m = len(regions)
    a = np.diag([r.area for r in regions])
    i, j = np.triu_indices(m, 1)
    if len(i):
        a[i, j] = a[j, i] = intersection_areas([[regions[p], regions[q]] for p, q in zip(i, j, strict=True)])
    return a


def needs_split(a: np.ndarray, v_min: float) -> bool:
    """Algorithm 1, step 8: split when some A_a(i, j) < V_min (i != j)."""
    off = a[~np.eye(len(a), dtype=bool)]
    return bool(len(off) and off.min() < v_min)


def spectral_partition(a: np.ndarray, k: int) -> np.ndarray:
    """Partition the intersection graph into k groups by spectral clustering ([21]: the k leading eigenvectors of the
    normalised affinity, rows normalised, then k-means; Ng, Jordan, Weiss 2001). k-means is scipy's `kmeans` started
    from farthest-first centres (robot 0's row, then the row farthest from those chosen): deterministic, so every robot
    computing it gets the same answer (Remark 1). Returns labels 0..k-1."""
    w = np.array(a, float)
    np.fill_diagonal(w, 0.0)
    w = w / max(w.max(), 1e-12) + 1e-6  # a tiny floor keeps the graph connected so the embedding is defined
    np.fill_diagonal(w, 0.0)
    d = 1.0 / np.sqrt(w.sum(axis=1))
    vals, vecs = np.linalg.eigh(d[:, None] * w * d[None, :])
    x = vecs[:, np.argsort(vals)[::-1][:k]]
    x /= np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-12)
    chosen = [0]
    for _ in range(1, k):
        chosen.append(int(np.linalg.norm(x[:, None] - x[chosen][None], axis=-1).min(axis=1).argmax()))
    centres, _ = kmeans(x, x[chosen].copy(), check_finite=False)  # Lloyd steps until the distortion settles
    labels, _ = vq(x, centres, check_finite=False)
    first_seen = list(dict.fromkeys(labels.tolist()))  # name groups in robot order, not k-means' order
    return np.array([first_seen.index(lab) for lab in labels.tolist()])


def split_team(a: np.ndarray, v_min_of: dict[int, float], max_parts: int) -> np.ndarray:
    """Algorithm 1, step 10, `graph partition(A_a)`: the paper does not say how many parts. We take the fewest parts
    k >= 2 (up to `max_parts`) after which no part needs to split again (every pair inside a part has A_a >= V_min of
    that part's size; a single robot always fits); failing that, `max_parts`. `v_min_of[size]` is V_min per team
    size."""
    m = len(a)
    labels = np.zeros(m, dtype=int)
    for k in range(2, min(max_parts, m) + 1):
        labels = spectral_partition(a, k)
        if len(set(labels.tolist())) < k:
            continue
        if all(
            len(idx := np.flatnonzero(labels == g)) < 2 or not needs_split(a[np.ix_(idx, idx)], v_min_of[len(idx)])
            for g in range(k)
        ):
            return labels
    return labels


def comm_components(comm: np.ndarray, members: list[int]) -> list[list[int]]:
    """Who a team's flooding reaches (Section IV-D, communication loss): consensus over a connected graph converges in
    at most d rounds, so after d rounds the robots a member has not heard from are those outside its connected
    component of the team's communication graph. Largest component first (ties: lowest robot id)."""
    sub = comm[np.ix_(members, members)]
    count, labels = connected_components(csr_matrix(sub & sub.T), directed=False)
    groups = [[members[i] for i in np.flatnonzero(labels == c)] for c in range(count)]
    return sorted(groups, key=lambda g: (-len(g), min(g)))


def merge_candidate(
    centre_k: np.ndarray, centre_l: np.ndarray, common_kl: Region, p_max: float, v_min: float, in_range: bool
) -> bool:
    """Section IV-C, the three conditions to merge sub-formations k and l: ||p_c^k - p_c^l|| <= p_max,
    V(P^k ∩ P^l) >= V_min, and some robot of k within communication range of some robot of l."""
    return bool(in_range and np.linalg.norm(centre_k - centre_l) <= p_max and common_kl.area >= v_min)


def merge_requests(
    teams: dict[int, list[int]], comm: np.ndarray, candidates: dict[tuple[int, int], float]
) -> dict[int, int]:
    """Algorithm 2: which team each team asks to merge with (0 rounds of consensus needed when it has none).

    `candidates[(k, l)] = V(P^k ∩ P^l)` for every ordered pair meeting the merge conditions. Steps 1-9: robot i of team
    k starts with Me_i(0) = the candidate team l it can talk to (one of its comm neighbours is in l) with the largest
    V; steps 10-14: d_k rounds in which each robot keeps its own or a neighbour's choice, whichever has the larger V.
    Returns {k: l} for teams whose robots settled on some l."""
    out = {}
    team_of = {i: k for k, mem in teams.items() for i in mem}
    for k, members in teams.items():
        choice = {}
        for i in members:
            heard = {team_of[j] for j in map(int, np.flatnonzero(comm[i])) if j in team_of and team_of[j] != k}
            options = [(candidates[(k, l)], -l) for l in heard if (k, l) in candidates]
            choice[i] = max(options) if options else (-np.inf, 0)
        for _ in range(max(len(members) - 1, 0)):  # d_k <= |I^k| - 1 rounds
            new = {}
            for i in members:
                best = choice[i]
                for j in np.flatnonzero(comm[i]):
                    if int(j) in choice and choice[int(j)] > best:
                        best = choice[int(j)]
                new[i] = best
            choice = new
        best = max(choice.values())
        if np.isfinite(best[0]):
            out[k] = -best[1]
    return out


def mutual_merges(requests: dict[int, int]) -> list[tuple[int, int]]:
    """Algorithm 2, last step: k and l merge when k asks for l and l asks for k."""
    return sorted({(min(k, l), max(k, l)) for k, l in requests.items() if requests.get(l) == k})


class StuckDetector:
    """Section IV-D, stuck faults: robot i is stuck when its progress towards its target, summed over n_dead
    consecutive steps, stays below Delta p_min. Steps where the robot is already near its target (within `near`) do not
    count, so a formation waiting at its slots is never flagged."""

    def __init__(self, n: int, n_dead: int, dp_min: float, near: float):
        self.n_dead, self.dp_min, self.near = n_dead, dp_min, near
        self.history: list[deque[float]] = [deque(maxlen=n_dead) for _ in range(n)]
        self.last: np.ndarray | None = None

    def reset(self, i: int) -> None:
        """Forget robot i's window (after it was dropped from or joined a team)."""
        self.history[i].clear()

    def update(self, position: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Record one step; (n,) bool: robots whose last n_dead steps all wanted progress and made < Delta p_min."""
        if self.last is None:
            self.last = position.copy()
            return np.zeros(len(position), dtype=bool)
        to_target = target - self.last
        dist = np.linalg.norm(to_target, axis=1)
        progress = np.einsum("id,id->i", position - self.last, to_target / np.maximum(dist, 1e-9)[:, None])
        self.last = position.copy()
        flags = np.zeros(len(position), dtype=bool)
        for i, h in enumerate(self.history):
            if dist[i] < self.near:
                h.clear()
                continue
            h.append(float(progress[i]))
            flags[i] = len(h) == self.n_dead and sum(h) < self.dp_min
        return flags


class TeamStall:
    """Ours, a guard against the deadlock Zhu et al. (ICRA 2019) warn of in Sec. VI ("deadlocks may still occur"): a
    team of robots lined up before a gap whose regions all end at the wall beside it fits its formation at the wall
    and never fails Algorithm 1's split check (every pair of regions overlaps widely before the wall). Sec. IV-D's
    stuck rule, read for a team: a team whose centre stays more than `max_lag` from p_r and moves less than Delta
    p_min in `window` seconds is stalled, and splits (docs/zhu.md). Keyed by the team's members, so a team that
    splits or merges starts a new window."""

    def __init__(self, window: float, dp_min: float):
        self.window, self.dp_min = window, dp_min
        self.since: dict[tuple[int, ...], tuple[float, np.ndarray]] = {}  # members -> (window start, centre then)

    def update(
        self, t: float, teams: dict[tuple[int, ...], tuple[np.ndarray, float]], max_lag: float
    ) -> list[tuple[int, ...]]:
        """Record each team's centre and distance from p_r at time t; the teams of two or more robots stalled."""
        self.since = {members: self.since[members] for members in teams if members in self.since}
        stalled = []
        for members, (centre, lag) in teams.items():
            start, then = self.since.setdefault(members, (t, centre))
            if lag <= max_lag or np.linalg.norm(centre - then) >= self.dp_min:  # near p_r, or moving: a new window
                self.since[members] = (t, centre)
            elif t - start >= self.window - 1e-9 and len(members) > 1:
                stalled.append(members)
        return stalled
