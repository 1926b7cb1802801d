"""Geometry derived from a scenario, never typed by hand: clearance, narrowest passage (STAF's eta), shortest path.

All static obstacles are capsules (segment + radius) and solid polygons (see scenario.py). Distances are exact for
capsules; the passage width and the path are computed on a grid of `resolution` metres (0.05 by default), so they are
exact up to that resolution (1/1200 of the world's larger side by default).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from stafpipe.distances import capsule_parts, closest_points, distance_to, inside_is_zero
from stafpipe.scenario import Scenario

SEARCH_BOUNDS = ((1.5, 2.0), (6.0, 8.0))
"""Path costs (m) a shortest-path search stops at, tried in turn before a search of the whole grid: (factor, margin) of
factor x the straight distance between the two points + margin: a search expands every cell cheaper than its bound,
and most ways through a map are less than 1.5 times as long as the straight line, so most searches stop long before
the grid's far end (a 30 x 12 m world is 576,000 cells; a full search takes about 0.8 s). The distances within the
bound are the whole search's; where two ways tie to the last bit the bounded search may take the other one (its heap
holds fewer cells), of the same length. `benchmarks/path_search.py`: on 156 legs of the 15 built-in and 40 generated
maps every path came out the same cell for cell; the built-in maps' routes are searched 2.35x faster, a generated
map's one leg across the world no faster (docs/decisions.md, "Bounded path searches")."""
CHUNK_BYTES = 256 * 2**20
"""Bytes the clearance grid's temporaries may take at once (four arrays of blocks x cells x candidates x 2 floats):
a map of 10,000 small obstacles asked for 3.35 GiB in one piece."""


def capsule_arrays(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A scenario's static obstacles as arrays: segment starts (C, 2), ends (C, 2), radii (C,)."""
    return capsule_parts(scenario.capsules)


def obstacle_distance(points: np.ndarray, scenario: Scenario) -> np.ndarray:
    """Distance (P,) from each point to the nearest static obstacle surface; 0 inside a solid polygon."""
    return distance_to(points, scenario.capsules, scenario.polygons, scenario.occupancy)


def _inside_is_zero(d: np.ndarray, points: np.ndarray, scenario: Scenario) -> np.ndarray:
    return inside_is_zero(d, points, scenario.polygons, scenario.occupancy)


def grid_clearance(xs: np.ndarray, ys: np.ndarray, scenario: Scenario, block: int = 8) -> np.ndarray:
    """`obstacle_distance` at every cell centre (H, W) of the grid xs (W,) x ys (H,), the same numbers computed
    against fewer capsules: the cells are taken in blocks of `block` x `block`, and a capsule can be the nearest to a
    cell of a block only if its distance from the block's centre is within twice the block's half-diagonal h of the
    nearest capsule's (a distance moves by at most h between the centre and any cell of the block). Most blocks then
    have one or two candidates instead of every capsule (40 generated maps: 50 -> 9 s, every cell the same)."""
    a, b, r = capsule_arrays(scenario)
    h_cells, w_cells = len(ys), len(xs)
    if len(r) <= 4 or block <= 1 or h_cells < 2 or w_cells < 2:  # little to leave out
        points = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), axis=-1).reshape(-1, 2)
        return obstacle_distance(points, scenario).reshape(h_cells, w_cells)
    rows, cols = -(-h_cells // block), -(-w_cells // block)
    # each block's centre and half-diagonal, from the cells it holds (the last row and column of blocks may be short)
    first_y, first_x = np.arange(rows) * block, np.arange(cols) * block
    last_y, last_x = np.minimum(first_y + block, h_cells) - 1, np.minimum(first_x + block, w_cells) - 1
    cy, hy = (ys[first_y] + ys[last_y]) / 2, (ys[last_y] - ys[first_y]) / 2
    cx, hx = (xs[first_x] + xs[last_x]) / 2, (xs[last_x] - xs[first_x]) / 2
    centres = np.stack(np.broadcast_arrays(cx[None, :], cy[:, None]), axis=-1).reshape(-1, 2)
    half = np.hypot(hx[None, :], hy[:, None]).ravel()
    to_centre = np.linalg.norm(centres[:, None, :] - closest_points(centres, a, b), axis=-1) - r  # (B, C)
    near = to_centre <= to_centre.min(axis=1, keepdims=True) + 2 * half[:, None] + 1e-9
    count = near.sum(axis=1)
    # each block's candidates first, the rest of its row a repeat of its first (a repeat does not change a minimum)
    order = np.argsort(~near, axis=1, kind="stable")
    candidates = np.where(np.take_along_axis(near, order, axis=1), order, order[:, :1])
    # the cells block by block (B, block * block, 2), the grid padded past its end to whole blocks (cut off after)
    pad_x = xs[0] + np.arange(cols * block) * (xs[1] - xs[0])
    pad_y = ys[0] + np.arange(rows * block) * (ys[1] - ys[0])
    pad_x[:w_cells], pad_y[:h_cells] = xs, ys
    cells = np.stack(np.broadcast_arrays(pad_x[None, :], pad_y[:, None]), axis=-1)
    cells = cells.reshape(rows, block, cols, block, 2).transpose(0, 2, 1, 3, 4).reshape(rows * cols, block * block, 2)
    d = np.empty(cells.shape[:2])
    by_count = np.argsort(count, kind="stable")  # blocks with as many candidates together
    start = 0
    while start < len(cells):  # chunks keep the (blocks, cells, K, 2) temporaries within CHUNK_BYTES
        k_most = int(count[by_count[min(start + 2_000, len(cells)) - 1]])  # sorted: the chunk's largest K
        size = int(max(1, min(2_000, CHUNK_BYTES // (block * block * max(k_most, 1) * 2 * 8 * 4))))
        part = by_count[start : start + size]
        k = int(count[part].max())
        ca, cb, cr = (x[candidates[part, :k]] for x in (a, b, r))
        cp = closest_points(cells[part], ca, cb)
        d[part] = (np.linalg.norm(cells[part][:, :, None, :] - cp, axis=-1) - cr[:, None, :]).min(axis=2)
        start += size
    d = d.reshape(rows, cols, block, block).transpose(0, 2, 1, 3).reshape(rows * block, cols * block)
    points = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), axis=-1).reshape(-1, 2)
    return _inside_is_zero(d[:h_cells, :w_cells].ravel(), points, scenario).reshape(h_cells, w_cells)


_SHARED: dict[str, Geometry] = {}
"""Geometry.of's cache: scenario content (its spec's repr) -> Geometry, the 16 most recently used."""


@dataclass
class Geometry:
    """Clearance grid of a scenario and what is derived from it."""

    scenario: Scenario
    resolution: float = 0.0
    """Grid cell size in metres; 0 picks 1/1200 of the world's larger side (0.025 m for a 30 m world)."""

    def __post_init__(self) -> None:
        if self.resolution <= 0:
            w = self.scenario.spec.world
            self.resolution = max(w.xmax - w.xmin, w.ymax - w.ymin) / 1200.0
        self._paths: dict[tuple[tuple[float, float], tuple[float, float], float], np.ndarray] = {}
        self._memo: dict[Any, Any] = {}

    def remember(self, key: Any, compute: Callable[[], Any]) -> Any:
        """`compute()` once per `key` for this scenario content (e.g. a plan's clearance profile along its path); an
        array comes back read-only, since every later caller shares it."""
        if key not in self._memo:
            value = compute()
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            self._memo[key] = value
        return self._memo[key]

    @classmethod
    def of(cls, scenario: Scenario) -> Geometry:
        """The Geometry of a scenario with this content, shared within the process: its clearance grid and its
        shortest paths are computed once, not once per episode (they took about half of an evaluation's time)."""
        key = repr(scenario.spec)
        found = _SHARED.pop(key, None) or cls(scenario)
        _SHARED[key] = found  # most recently used last
        while len(_SHARED) > 16:
            _SHARED.pop(next(iter(_SHARED)))
        return found

    @cached_property
    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell-centre x (W,), y (H,) and clearance (H, W): distance to the nearest obstacle, 0 inside one."""
        w = self.scenario.spec.world
        xs = np.arange(w.xmin + self.resolution / 2, w.xmax, self.resolution)
        ys = np.arange(w.ymin + self.resolution / 2, w.ymax, self.resolution)
        return xs, ys, grid_clearance(xs, ys, self.scenario)

    def _cell(self, point: tuple[float, float] | np.ndarray) -> tuple[int, int]:
        xs, ys, _ = self.grid
        return int(np.abs(ys - point[1]).argmin()), int(np.abs(xs - point[0]).argmin())

    def passage_width(self, start: tuple[float, float], goal: tuple[float, float]) -> float:
        """Narrowest passage on the way from start to goal (STAF's eta): twice the bottleneck clearance of the route
        that keeps farthest from obstacles, i.e. the widest disc that can travel from start to goal."""
        key = ("passage", float(start[0]), float(start[1]), float(goal[0]), float(goal[1]))
        return float(self.remember(key, lambda: self._passage_width(start, goal)))

    def _passage_width(self, start: tuple[float, float], goal: tuple[float, float]) -> float:
        _, _, clear = self.grid
        s, g = self._cell(start), self._cell(goal)
        lo, hi = 0.0, float(min(clear[s], clear[g]))
        for _ in range(30):  # bisection on the clearance level at which start and goal stay connected
            mid = (lo + hi) / 2
            labels, _ = ndimage.label(clear >= mid)
            if labels[s] != 0 and labels[s] == labels[g]:
                lo = mid
            else:
                hi = mid
            if hi - lo < self.resolution / 8:
                break
        return 2.0 * lo

    def shortest_path(self, start: tuple[float, float], goal: tuple[float, float], clearance: float) -> np.ndarray:
        """Shortest path (K, 2) from start to goal keeping `clearance` from obstacles (16-neighbour grid Dijkstra,
        then shortened along lines of sight). Raises ValueError if the goal cannot be reached. Remembered per
        (start, goal, clearance): every episode of an eval asks for the same legs."""
        key = ((float(start[0]), float(start[1])), (float(goal[0]), float(goal[1])), float(clearance))
        if key not in self._paths:
            self._paths[key] = self._shortest_path(start, goal, clearance)
        return self._paths[key].copy()

    def _graph(self, clearance: float) -> Any:
        """The free cells' 16-neighbour graph (CSR) at this clearance, built once: every episode of L&F asks for a path
        from its own perturbed start, and building the graph was half of each search."""

        def build() -> Any:
            _xs, _ys, clear = self.grid
            free = clear >= clearance
            h, w = free.shape
            idx = np.arange(h * w).reshape(h, w)
            rows, cols, costs = [], [], []
            for di, dj in [(0, 1), (1, 0), (1, 1), (1, -1), (1, 2), (2, 1), (1, -2), (2, -1)]:
                i0, i1 = max(0, -di), h - max(0, di)
                j0, j1 = max(0, -dj), w - max(0, dj)
                a, b = idx[i0:i1, j0:j1], idx[i0 + di : i1 + di, j0 + dj : j1 + dj]
                ok = free[i0:i1, j0:j1] & free[i0 + di : i1 + di, j0 + dj : j1 + dj]
                rows.append(a[ok])
                cols.append(b[ok])
                costs.append(np.full(int(ok.sum()), math.hypot(di, dj) * self.resolution))
            shape = (h * w, h * w)
            return coo_matrix(
                (np.concatenate(costs), (np.concatenate(rows), np.concatenate(cols))), shape=shape
            ).tocsr()

        return self.remember(("graph", float(clearance)), build)

    def _shortest_path(self, start: tuple[float, float], goal: tuple[float, float], clearance: float) -> np.ndarray:
        s, g = self._node(start), self._node(goal)
        dist, pred, _ = self._search(clearance, s, g, math.dist(start, goal))
        return self._pulled(self._trace(dist, pred, g, s, (start, goal, clearance))[::-1], start, goal, clearance)

    def _search(
        self, clearance: float, root: int, target: int, straight: float, after: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """(dist, pred, bound) of a Dijkstra search from `root` over the free cells at `clearance`, stopped at the
        first of SEARCH_BOUNDS above `after` that reaches `target`, else over the whole grid (inf)."""
        graph = self._graph(clearance)
        bounds = [b for b in (factor * straight + margin for factor, margin in SEARCH_BOUNDS) if b > after]
        for bound in [*bounds, math.inf]:
            dist, pred = dijkstra(graph, directed=False, indices=root, return_predecessors=True, limit=bound)
            if np.isfinite(dist[target]):
                break
        return dist, pred, bound

    def path_to(self, start: tuple[float, float], goal: tuple[float, float], clearance: float) -> np.ndarray:
        """As `shortest_path`, read from one Dijkstra tree rooted at the goal, kept per (goal, clearance): for many
        starts and one goal (L&F's leader from each episode's own perturbed start), one search instead of one per
        start. The same length as `shortest_path`'s; where two ways tie it may take the other."""
        g, s = self._node(goal), self._node(start)
        key = ("tree", g, float(clearance))
        tree = self._memo.get(key)
        if tree is None or not (np.isfinite(tree[0][s]) or math.isinf(tree[2])):  # a start beyond the tree's bound
            done = 0.0 if tree is None else tree[2]
            tree = self._memo[key] = self._search(clearance, g, s, math.dist(start, goal), done)
        dist, pred, _ = tree
        return self._pulled(self._trace(dist, pred, s, g, (start, goal, clearance)), start, goal, clearance)

    def _node(self, point: tuple[float, float]) -> int:
        i, j = self._cell(point)
        return i * len(self.grid[0]) + j

    @staticmethod
    def _trace(dist: np.ndarray, pred: np.ndarray, node: int, root: int, asked: tuple) -> np.ndarray:
        """Grid nodes from `node` back to the search's `root` along the predecessors; `asked` (start, goal,
        clearance) names the search in the error where there is no way."""
        if not np.isfinite(dist[node]):
            raise ValueError("no path from {} to {} with clearance {}".format(*asked))
        cells = [node]
        while cells[-1] != root:
            cells.append(pred[cells[-1]])
        return np.array(cells)

    def _pulled(self, cells: np.ndarray, start, goal, clearance: float) -> np.ndarray:
        """Grid nodes (start to goal) as points, the ends replaced by start and goal, shortened along lines of sight."""
        xs, ys, _ = self.grid
        pts = np.stack([xs[cells % len(xs)], ys[cells // len(xs)]], axis=1)
        pts[0], pts[-1] = start, goal
        return self._pull_string(pts, clearance)

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Clearance (..) of points (.., 2) read from the grid (the nearest cell; outside the world: the edge cell)."""
        xs, ys, clear = self.grid
        # both axes at once (the plan reads the grid at every control step): the nearest cell, within the grid
        cell = np.rint((points - (xs[0], ys[0])) / self.resolution).astype(int)
        cell = np.minimum(np.maximum(cell, 0), (len(xs) - 1, len(ys) - 1))
        return clear[cell[..., 1], cell[..., 0]]

    def visible(self, p: np.ndarray, q: np.ndarray, clearance: float) -> bool:
        """Whether the straight way from p to q keeps `clearance` (m) from every obstacle (sampled every half cell)."""
        k = max(2, int(np.linalg.norm(q - p) / (self.resolution / 2)) + 1)
        samples = p + np.linspace(0.0, 1.0, k)[:, None] * (q - p)
        return bool((self.clearance(samples) >= clearance).all())

    def _pull_string(self, pts: np.ndarray, clearance: float) -> np.ndarray:
        out, anchor, j = [pts[0]], 0, 1
        while j < len(pts):
            if not self.visible(pts[anchor], pts[j], clearance):
                anchor = j - 1
                out.append(pts[anchor])
            j += 1
        out.append(pts[-1])
        return np.array(out)


def lengths(v: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """np.linalg.norm(v, axis=-1): its own sum of squares and root, without its wrapper's call cost (the control
    step takes several)."""
    return np.sqrt((v * v).sum(axis=-1, keepdims=keepdims))


class PathFrame:
    """Arc-length parametrisation of a polyline path (K, 2): positions, headings, projections. `extend`: the path
    reaches back straight behind its start (arc lengths below 0), so that slots placed behind the start do not all
    fall on the start point."""

    def __init__(self, path: np.ndarray, extend: bool = False) -> None:
        self.extend = extend
        path = np.asarray(path, float)
        keep = np.concatenate([[True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-9])
        self.path = path[keep] if keep.sum() >= 2 else np.stack([path[0], path[0] + [1e-6, 0.0]])
        seg = np.diff(self.path, axis=0)
        self.seg_len = np.linalg.norm(seg, axis=1)
        self.unit = seg / self.seg_len[:, None]
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.length = float(self.cum[-1])
        self.heading = np.arctan2(self.unit[:, 1], self.unit[:, 0])
        self._cum, self._points, self._units = self.cum.tolist(), self.path.tolist(), self.unit.tolist()  # for `at`
        # where a projection may fall on each segment: the first reaches back when extended
        self.seg_from = np.zeros(len(self.seg_len))
        if extend:
            self.seg_from[0] = -np.inf

    def at(self, s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Points (.., 2) and headings (..) at arc lengths s (clipped to the path, or only at its end if extended)."""
        if isinstance(s, float | int):  # one arc length: the same arithmetic on plain floats, without array setup
            one = min(float(s) if self.extend else max(float(s), 0.0), self.length)
            i = min(max(bisect.bisect_right(self._cum, one) - 1, 0), len(self.seg_len) - 1)
            along = one - self._cum[i]
            (px, py), (ux, uy) = self._points[i], self._units[i]
            return np.array([px + along * ux, py + along * uy]), self.heading[i]
        # np.minimum/np.maximum, not np.clip: the same values at a fraction of the call's cost (the plan calls `at`
        # and `progress` several times per control step: benchmarks/staf_decision_time.py)
        s = np.asarray(s, float)
        s = np.minimum(s if self.extend else np.maximum(s, 0.0), self.length)
        k = np.minimum(np.maximum(np.searchsorted(self.cum, s, side="right") - 1, 0), len(self.seg_len) - 1)
        point = self.path[k] + (s - self.cum[k])[..., None] * self.unit[k]
        return point, self.heading[k]

    def progress(self, points: np.ndarray, near: np.ndarray | None = None, window: float = 2.0) -> np.ndarray:
        """Arc length (P,) of each point's projection on the path: on the nearest segment, or with `near` (P,) on the
        nearest of the segments that reach within `window` m of arc length of near[p] (a path that comes back close
        to itself, a loop or a hairpin round a thin wall, then keeps each point on its own part of the way)."""
        t = np.einsum("pkd,kd->pk", points[:, None] - self.path[None, :-1], self.unit)
        t = np.minimum(np.maximum(t, self.seg_from), self.seg_len)
        proj = self.path[None, :-1] + t[..., None] * self.unit[None]
        off = lengths(points[:, None] - proj)
        if near is not None:
            below = np.where(np.isinf(self.seg_from), -np.inf, self.cum[:-1])  # an extended first segment: all behind
            off = np.where(beyond_window(below, self.cum[1:], near, window), np.inf, off)
        k = off.argmin(axis=1)
        return self.cum[k] + t[np.arange(len(points)), k]

    def lateral(self, points: np.ndarray, progress: np.ndarray | None = None) -> np.ndarray:
        """Signed distance (P,) of each point from the path, left positive; `progress`: the points' `progress` where
        the caller has it already."""
        point, heading = self.at(self.progress(points) if progress is None else progress)
        d = points - point
        return np.cos(heading) * d[:, 1] - np.sin(heading) * d[:, 0]


def path_length(path: np.ndarray) -> float:
    """Length of a polyline (K, 2)."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def path_parts(path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A polyline's (K, 2) segments (K-1, 2), their lengths (K-1,) and the arc length at each vertex (K,), as
    `point_ahead` uses them (a caller that asks every step of the same path computes them once)."""
    seg = np.diff(path, axis=0)
    length = np.maximum(np.linalg.norm(seg, axis=1), 1e-9)
    return seg, length, np.concatenate([[0.0], np.cumsum(length)])


def beyond_window(start: np.ndarray, end: np.ndarray, near: np.ndarray, window: float) -> np.ndarray:
    """(P, K) True where segment k, spanning arc lengths start[k]..end[k], lies wholly more than `window` m of arc
    length from near[p]: the segments a point tracked along a path may not be projected on."""
    return (end[None] < near[:, None] - window) | (start[None] > near[:, None] + window)


def point_ahead(
    path: np.ndarray,
    points: np.ndarray,
    ahead: float,
    parts: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    near: np.ndarray | None = None,
    window: float = 2.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point (P, 2): the point `ahead` metres beyond its projection on the polyline `path` (K, 2) (capped at
    the end), the path's unit direction there, and the arc length still left after the projection; `parts`:
    `path_parts(path)` where the caller has them; `near` (P,): project on the segments within `window` m of arc
    length of near[p] only (as `PathFrame.progress`: a route that comes back near itself)."""
    seg, length, cum = path_parts(path) if parts is None else parts
    t = np.clip(np.einsum("pkd,kd->pk", points[:, None] - path[None, :-1], seg) / length**2, 0.0, 1.0)
    proj = path[None, :-1] + t[..., None] * seg[None]
    off = np.linalg.norm(points[:, None] - proj, axis=-1)
    if near is not None:
        off = np.where(beyond_window(cum[:-1], cum[1:], near, window), np.inf, off)
    k = off.argmin(axis=1)
    arc = cum[k] + t[np.arange(len(points)), k] * length[k]
    target = np.minimum(arc + ahead, cum[-1])
    j = np.clip(np.searchsorted(cum, target, side="right") - 1, 0, len(seg) - 1)
    direction = seg[j] / length[j][:, None]
    return path[j] + (target - cum[j])[:, None] * direction, direction, cum[-1] - arc
