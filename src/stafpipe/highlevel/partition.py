"""From soft assignments to subteams: hard assignment with repair, the adaptive number of subteams, the classical
partitions the learned cut is compared with, and the statistics every partition is judged by."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from sklearn.cluster import KMeans, SpectralClustering

from stafpipe.formations import formation_slots

LIST_SEARCH_UP_TO = 64
"""Up to this many robots the subteams' parts are found by a search on plain lists: a handful of robots is decided
within a control step (STAF's split, benchmarks/staf_decision_time.py), where numpy's per-call cost dominates."""


def _neighbours(n: int, edges: np.ndarray) -> list[list[int]]:
    """Each robot's neighbours (edges src -> dst, both directions listed), in edge order."""
    near: list[list[int]] = [[] for _ in range(n)]
    for i, j in zip(edges[0].tolist(), edges[1].tolist(), strict=True):
        near[i].append(j)
    return near


def _parts(near: list[list[int]], label: list[int]) -> list[int]:
    """Component id of each robot along the edges that stay inside a subteam: its component's lowest robot (starts
    in index order, so the first robot a search reaches is its component's lowest)."""
    part = [-1] * len(label)
    for start in range(len(label)):
        if part[start] >= 0:
            continue
        part[start], stack = start, [start]
        while stack:
            i = stack.pop()
            for j in near[i]:
                if part[j] < 0 and label[j] == label[i]:
                    part[j] = start
                    stack.append(j)
    return part


def _subteam_parts(labels: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Component id of every robot in the graph of edges that stay inside a subteam: its lowest robot (the search on
    lists for small teams), or scipy's component number."""
    n = len(labels)
    if n <= LIST_SEARCH_UP_TO:
        return np.array(_parts(_neighbours(n, edges), labels.tolist()), dtype=int)
    inside = labels[edges[0]] == labels[edges[1]]
    graph = coo_matrix((np.ones(inside.sum()), (edges[0][inside], edges[1][inside])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def connected_subteams(labels: np.ndarray, edges: np.ndarray, m: int) -> bool:
    """Every one of the m subteams non-empty and connected: the edges inside subteams join the robots into m parts."""
    label = labels.tolist()
    if set(label) != set(range(m)):
        return False
    if len(label) <= LIST_SEARCH_UP_TO:  # on the lists themselves: the plan's split asks this within a control step
        return len(set(_parts(_neighbours(len(label), edges), label))) == m
    return len(np.unique(_subteam_parts(labels, edges))) == m


def _most_common(values: list[int], length: int) -> int:
    """np.bincount(values, minlength=length).argmax(): the most frequent value, the smallest of a tie."""
    counts = [0] * max(length, max(values) + 1)
    for v in values:
        counts[v] += 1
    return counts.index(max(counts))


def repair(labels: np.ndarray, probs: np.ndarray, edges: np.ndarray, m: int) -> np.ndarray:
    """Make every one of the m subteams non-empty, and each connected in the radius graph where the graph allows.

    Empty subteam j: takes the robot most likely to be in j from the largest subteam. Disconnected subteam: each part
    but the largest moves to the subteam it shares most edges with (if it touches one). Repeats until nothing changes.
    Plain lists: a repair moves a few robots at a time, each step a short loop (numpy's per-call cost dominated at
    ten robots); ties go as argmax takes them, to the first.
    """
    n = len(labels)
    m = min(m, n)
    if connected_subteams(labels, edges, m):  # the common case: nothing to repair
        return labels.copy()
    lab, near, p = labels.tolist(), _neighbours(n, edges), probs.tolist()
    for _ in range(4 * n + 4):
        changed = False
        for j in range(m):
            if j not in lab:  # empty: the robot of the largest subteam most likely in j
                largest = _most_common(lab, m)
                donors = [i for i in range(n) if lab[i] == largest]
                lab[max(donors, key=lambda i: p[i][j])] = j  # max keeps the first of equals, as argmax
                changed = True
        part = _parts(near, lab)
        members: dict[int, list[int]] = {}
        for i, q in enumerate(part):
            members.setdefault(q, []).append(i)
        for j in range(m):
            parts = sorted({part[i] for i in range(n) if lab[i] == j})
            keep = max(parts, key=lambda q: len(members[q]))
            for q in (q for q in parts if q != keep):
                others = [lab[k] for i in members[q] for k in near[i] if lab[k] != j]
                if others:  # one move, then the parts are recomputed: they changed
                    to = _most_common(others, m)
                    for i in members[q]:
                        lab[i] = to
                    changed = True
                    break
            if changed:
                break
        if not changed:
            break
    return np.array(lab, dtype=labels.dtype)


def hard_assignment(probs: np.ndarray, edges: np.ndarray, m: int) -> np.ndarray:
    """argmax of Y over the first m subteams, then `repair`."""
    return repair(probs[:, :m].argmax(axis=1), probs, edges, m)


def formation_width(kind: str, k: int, spacing: float, robot_radius: float, angle_deg: float = 90.0) -> float:
    """Width (m) of a k-robot formation across its heading, robot bodies included."""
    if k <= 1:
        return 2 * robot_radius
    slots = formation_slots(kind, k, spacing, angle_deg)
    return float(slots[:, 1].max() - slots[:, 1].min()) + 2 * robot_radius


def choose_m(
    kind: str, n: int, eta: float, robot_radius: float, safe_gap: float, m_max: int, angle_deg: float = 90.0
) -> tuple[int, bool]:
    """Adaptive number of subteams (STAF Section 7, limitation 3): the smallest m such that a subteam of ceil(n/m)
    robots in the team's formation, at its tightest safe spacing (2 r + safe_gap), fits the passage width eta.

    Returns (m, fits); when even m_max subteams do not fit, (m_max, False).
    """
    spacing = 2 * robot_radius + safe_gap
    for m in range(1, max(1, min(m_max, n)) + 1):
        if formation_width(kind, math.ceil(n / m), spacing, robot_radius, angle_deg) <= eta:
            return m, True
    return max(1, min(m_max, n)), False


def partition_stats(
    labels: np.ndarray, pos: np.ndarray, goal: np.ndarray, edges: np.ndarray, m: int
) -> dict[str, float]:
    """What a partition is judged by: sizes, cut edges, subteam-goal distance (as in loss.py), connectivity."""
    n = len(labels)
    sizes = np.bincount(labels, minlength=m)[:m]
    cut = float((labels[edges[0]] != labels[edges[1]]).mean()) if edges.shape[1] else 0.0
    d_team = max(float(np.linalg.norm(pos.mean(0) - goal.mean(0))), 1e-9)
    gaps = [
        sizes[j] / n * np.linalg.norm(pos[labels == j].mean(0) - goal[labels == j].mean(0))
        for j in range(m)
        if sizes[j]
    ]
    part = _subteam_parts(labels, edges)
    connected = all(len(np.unique(part[labels == j])) <= 1 for j in range(m))
    return {
        "size_min": float(sizes.min()),
        "size_max": float(sizes.max()),
        "imbalance": float(sizes.max() - sizes.min()),
        "empty_subteams": float((sizes == 0).sum()),
        "subteams_used": float((sizes > 0).sum()),
        "cut_fraction": cut,
        "goal_distance": float(np.sum(gaps) / d_team),
        "connected": float(connected),
    }


def spectral_partition(
    pos: np.ndarray, goal: np.ndarray, edges: np.ndarray, m: int, radius: float, seed: int
) -> np.ndarray:
    """Spectral clustering (scikit-learn) of the radius graph weighted by start and goal proximity."""
    n = len(pos)
    if m <= 1:
        return np.zeros(n, dtype=int)
    d2 = ((pos[edges[0]] - pos[edges[1]]) ** 2).sum(1) + ((goal[edges[0]] - goal[edges[1]]) ** 2).sum(1)
    w = np.exp(-d2 / (2 * radius**2))
    affinity = coo_matrix((w, (edges[0], edges[1])), shape=(n, n)).toarray() + 1e-6  # tiny floor: a connected graph
    sc = SpectralClustering(n_clusters=m, affinity="precomputed", random_state=seed, assign_labels="kmeans")
    return sc.fit_predict(affinity)


def _balanced_seats(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Seats for a min-cost assignment that gives every one of m subteams floor(n/m) or ceil(n/m) robots: floor(n/m)
    required seats per subteam (a bonus that outweighs any cost, so all are taken) and one optional seat each."""
    low = n // m
    seats = np.concatenate([np.repeat(np.arange(m), low), np.arange(m)])
    required = np.arange(len(seats)) < m * low
    return seats, required


def _assign_to_seats(cost: np.ndarray, m: int) -> np.ndarray:
    """Labels from a (n, m) robot-to-subteam cost: min-cost assignment (scipy) onto `_balanced_seats`."""
    n = len(cost)
    seats, required = _balanced_seats(n, m)
    seat_cost = cost[:, seats] - required * (1.0 + 2.0 * float(np.abs(cost).max()) * n)
    rows, cols = linear_sum_assignment(seat_cost)
    labels = np.empty(n, dtype=int)
    labels[rows] = seats[cols]
    return labels


def balance_sizes(labels: np.ndarray, pos: np.ndarray, m: int) -> np.ndarray:
    """Subteam sizes within one of each other (floor(n/m) or ceil(n/m)), keeping the given subteams where they already
    are; otherwise each robot goes to the nearest subteam centroid that has a seat left (min-cost assignment).

    Why: STAF's cut loss has a balance term (Eq. (1), Fig. 7) but the shipped network's argmax at m = 4 leaves a subteam
    empty and the repair gives it one robot (docs/method.md): a one-robot "line" cannot keep a formation. Used by STAF's
    plan (`plan.balance`); docs/staf_planned.md.
    """
    labels = np.asarray(labels, dtype=int)
    n, m = len(labels), min(m, len(labels))
    sizes = np.bincount(labels, minlength=m)[:m]
    if m <= 1 or (sizes.min() >= n // m and sizes.max() <= -(-n // m)):
        return labels.copy()
    centres = np.stack([pos[labels == j].mean(0) if sizes[j] else pos.mean(0) for j in range(m)])
    return _assign_to_seats(((pos[:, None, :] - centres[None]) ** 2).sum(-1), m)


def balanced_kmeans(pos: np.ndarray, goal: np.ndarray, m: int, seed: int, iters: int = 20) -> np.ndarray:
    """k-means on (start, goal) with equal sizes (within one): Lloyd steps whose assignment step is a min-cost
    assignment of robots to floor(n/m) required and one optional seat per cluster (scipy's linear_sum_assignment)."""
    n = len(pos)
    if m <= 1:
        return np.zeros(n, dtype=int)
    x = np.concatenate([pos - pos.mean(0), goal - goal.mean(0)], axis=1)
    centres = KMeans(n_clusters=m, n_init=4, random_state=seed).fit(x).cluster_centers_
    labels = np.full(n, -1)
    for _ in range(iters):
        new = _assign_to_seats(((x[:, None, :] - centres[None, :, :]) ** 2).sum(-1), m)
        if (new == labels).all():
            break
        labels = new
        centres = np.stack([x[labels == j].mean(0) for j in range(m)])
    return labels
