"""Obstacle-free convex regions in the plane, as Zhu et al. 2019 (Section II, "Obstacle-free convex region", after
Alonso-Mora et al. [20], which uses IRIS) need them: grow, intersect, measure, and fit a formation inside.

A region is a convex polygon kept twice: as half-planes {x : normals @ x <= offsets} (intersections and fitting are
then stacking and shifting rows) and as its counter-clockwise vertices (for areas and drawing). Regions live in the
space of robot centres: obstacles are dilated by the robot radius first (Zhu's O~_i).

Growing (2D, one IRIS step with a point seed; see docs/zhu.md for why no ellipsoid iterations): start from the
visibility disc B_i (a regular polygon inscribed in radius r_B, 8 sides by default: 90 % of the disc's area);
repeatedly take the remaining obstacle nearest to the seed, add the half-plane tangent to its dilated surface at the
point closest to the seed, and drop every obstacle that lies wholly beyond the new half-plane. Moving obstacles enter
as capsules swept over the horizon tau (the projection of
Zhu's position-time obstacle (1) onto the plane).

Polygons are computed from half-planes by enumerating the crossings of every pair of lines that satisfy all
constraints, for a whole batch of polygons in one numpy expression: scipy's HalfspaceIntersection needs a strictly
interior point (an LP) and costs ~110 us per call, shapely ~40 us per intersection, which is too much for Table I's
budget of a few milliseconds per cycle (see docs/zhu.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial import ConvexHull

from stafpipe.geometry import closest_points

_EPS = 1e-9


@dataclass(frozen=True)
class Region:
    """A convex polygon: half-planes normals (m, 2) @ x <= offsets (m,), and its vertices (k, 2) counter-clockwise
    (k = 0 when empty)."""

    normals: np.ndarray
    offsets: np.ndarray
    vertices: np.ndarray
    area: float
    """Zhu's V(P) (Section IV-B: "the size of a convex region"): its area in m^2."""

    @property
    def empty(self) -> bool:
        return len(self.vertices) < 3

    def contains(self, points: np.ndarray, tol: float = 1e-7) -> np.ndarray:
        """(P,) bool: points (P, 2) inside."""
        return (np.atleast_2d(points) @ self.normals.T <= self.offsets + tol).all(axis=1)


def polygon_area(vertices: np.ndarray) -> float:
    """Shoelace area of a simple polygon (k, 2); 0 for fewer than 3 vertices."""
    if len(vertices) < 3:
        return 0.0
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


@lru_cache(maxsize=64)
def _pairs(m: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(m, 1)


def polygons(
    normals: np.ndarray, offsets: np.ndarray, tol: float = 1e-7, area_only: bool = False
) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """B convex polygons {x : normals[b] @ x <= offsets[b]}: normals (B, m, 2), offsets (B, m); padding rows are
    normals 0, offsets 1. Every vertex is the crossing of two lines that satisfies all constraints, enumerated for all
    B at once. Returns the vertices (counter-clockwise, (k, 2) each), the areas (B,), and which rows are edges (B, m);
    with `area_only`, just the areas (the vertex list and edge mask come back empty)."""
    normals, offsets = np.asarray(normals, float), np.asarray(offsets, float)
    b_idx = np.arange(len(normals))[:, None]
    i, j = _pairs(normals.shape[1])
    ni, nj, ci, cj = normals[:, i], normals[:, j], offsets[:, i], offsets[:, j]
    det = ni[..., 0] * nj[..., 1] - ni[..., 1] * nj[..., 0]
    ok = np.abs(det) > 1e-12
    det = np.where(ok, det, 1.0)
    pts = np.stack([(ci * nj[..., 1] - cj * ni[..., 1]) / det, (ni[..., 0] * cj - nj[..., 0] * ci) / det], axis=-1)
    ok &= (pts @ normals.transpose(0, 2, 1) <= offsets[:, None, :] + tol).all(axis=-1)
    count = ok.sum(axis=1)
    centre = (pts * ok[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None]
    angle = np.where(ok, np.arctan2(pts[..., 1] - centre[:, None, 1], pts[..., 0] - centre[:, None, 0]), np.inf)
    order = np.argsort(angle, axis=1)
    pts, ok = pts[b_idx, order], ok[b_idx, order]
    # a vertex where more than two lines cross appears once per pair of them: keep the first copy
    new = ok.copy()
    new[:, 1:] &= np.abs(pts[:, 1:] - pts[:, :-1]).max(axis=-1) > tol
    # shoelace over the sorted points with every dropped entry replaced by the last kept one (it adds zero area)
    last = np.maximum.accumulate(np.where(new, np.arange(pts.shape[1]), 0), axis=1)
    filled = pts[b_idx, last]
    first = filled[:, :1]
    nxt = np.concatenate([filled[:, 1:], first], axis=1)
    area = 0.5 * np.abs((filled[..., 0] * nxt[..., 1] - filled[..., 1] * nxt[..., 0]).sum(axis=1))
    if area_only:  # fewer than 3 distinct vertices enclose no area anyway
        return [], area, np.zeros((0, 0), dtype=bool)
    vertices = [pts[b][new[b]] for b in range(len(normals))]
    for b, v in enumerate(vertices):
        if len(v) > 1 and np.abs(v[0] - v[-1]).max() <= tol:  # the angle wrapped round onto the first vertex
            vertices[b] = v[:-1]
        if len(vertices[b]) < 3:
            area[b] = 0.0
    # a row is an edge when at least two distinct vertices lie on its line
    on_line = np.abs(filled @ normals.transpose(0, 2, 1) - offsets[:, None, :]) <= 1e-6  # (B, P, m)
    edges = (on_line & new[..., None]).sum(axis=1) >= 2
    return vertices, area, edges


def _padded(rows: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    m = max(len(c) for _, c in rows)
    normals, offsets = np.zeros((len(rows), m, 2)), np.ones((len(rows), m))
    for b, (n, c) in enumerate(rows):
        normals[b, : len(c)], offsets[b, : len(c)] = n, c
    return normals, offsets


_EMPTY = (np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([0.0, -1.0]))  # x <= 0 and x >= 1


def regions_from_halfplanes(rows: list[tuple[np.ndarray, np.ndarray]]) -> list[Region]:
    """Regions of half-plane sets [(normals (m, 2), offsets (m,)), ...], each kept as its own edges only (the
    redundant half-planes dropped, so later intersections stay small)."""
    normals, offsets = _padded(rows)
    vertices, area, edges = polygons(normals, offsets)
    return [
        Region(normals[b][edges[b]], offsets[b][edges[b]], v, float(area[b]))
        if len(v) >= 3
        else Region(*_EMPTY, v[:0], 0.0)
        for b, v in enumerate(vertices)
    ]


def halfplanes_of(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward half-planes (unit normals) of a counter-clockwise convex polygon (k, 2)."""
    edges = np.roll(vertices, -1, axis=0) - vertices
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), _EPS)
    return normals, np.einsum("kd,kd->k", normals, vertices)


def disc_polygon(centre: np.ndarray, radius: float, sides: int = 8) -> np.ndarray:
    """Vertices of the regular polygon with `sides` inscribed in a disc (Zhu's field of view B_i in 2D)."""
    theta = 2.0 * math.pi * np.arange(sides) / sides
    return np.asarray(centre, float) + radius * np.stack([np.cos(theta), np.sin(theta)], axis=1)


@lru_cache(maxsize=8)
def _disc(radius: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    return halfplanes_of(disc_polygon(np.zeros(2), radius, sides))


def grow_halfplanes(
    seeds: np.ndarray,
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    seg_r: np.ndarray,
    visibility: float,
    inflate: float,
    ahead: np.ndarray | None = None,
    behind: float = math.inf,
    sides: int = 8,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Half-planes of each robot's obstacle-free convex region P_i (Zhu Section II) around its seed (P, 2) within
    `visibility` (r_B; the disc as a regular polygon of `sides`), avoiding capsules (seg_a, seg_b, seg_r) dilated by
    `inflate` (the robot radius). With unit directions `ahead` (P, 2), each region also stops `behind` metres behind
    its seed (ours: "likely to make progress", see docs/zhu.md)."""
    seeds = np.atleast_2d(np.asarray(seeds, float))
    disc_n, disc_c = _disc(visibility, sides)
    reach = seg_r + inflate
    cps = closest_points(seeds, seg_a, seg_b) if len(seg_r) else np.zeros((len(seeds), 0, 2))
    dists = np.linalg.norm(cps - seeds[:, None], axis=-1)
    out = []
    for i, seed in enumerate(seeds):
        rows_n, rows_c = [disc_n], [disc_c + disc_n @ seed]
        if ahead is not None and math.isfinite(behind):
            rows_n.append(-ahead[i][None])
            rows_c.append(np.array([behind - float(ahead[i] @ seed)]))
        cp, dist = cps[i], dists[i]
        gap = dist - reach
        remaining = gap < visibility  # Zhu's O_i = B_i ∩ O: only what the robot sees
        for k in np.argsort(gap)[: int(remaining.sum())]:  # nearest first; a dropped obstacle is skipped
            if not remaining[k]:
                continue
            n = (cp[k] - seed) / max(dist[k], _EPS)
            # tangent to the dilated obstacle at its point nearest the seed; inside an obstacle (a contact), the
            # half-plane passes through the seed so the region stays on the free side
            c = float(n @ cp[k] - reach[k]) if gap[k] > 0 else float(n @ seed)
            rows_n.append(n[None])
            rows_c.append(np.array([c]))
            remaining &= np.minimum(seg_a @ n, seg_b @ n) - reach < c - _EPS  # drop what lies wholly beyond
        out.append((np.concatenate(rows_n), np.concatenate(rows_c)))
    return out


def intersect_all(groups: list[list[Region]], fan_in: int = 4) -> list[Region]:
    """For each group of regions, their intersection (Zhu's P_ij = P_i ∩ P_j and P = ∩ P_i). All groups go in one
    batch, `fan_in` regions at a time, reducing each result to its edges before the next round (a tree), so a team of
    100 never stacks 100 regions' half-planes into one enumeration."""
    current = [list(g) for g in groups]
    while True:
        chunks = [(k, g[s : s + fan_in]) for k, g in enumerate(current) if len(g) > 1 for s in range(0, len(g), fan_in)]
        if not chunks:
            return [g[0] for g in current]
        done = regions_from_halfplanes(_stacked([c for _, c in chunks]))
        merged: list[list[Region]] = [[] if len(g) > 1 else g for g in current]
        for (k, _), region in zip(chunks, done, strict=True):
            merged[k].append(region)
        current = merged


def intersection_areas(groups: list[list[Region]]) -> np.ndarray:
    """V(∩ group) for each group, when only the sizes are needed (Zhu's A_a(i, j), Algorithm 1 step 7)."""
    return polygons(*_padded(_stacked(groups)), area_only=True)[1]


def _stacked(groups: list[list[Region]]) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(np.concatenate([r.normals for r in g]), np.concatenate([r.offsets for r in g])) for g in groups]


def hull_vertices(slots: np.ndarray) -> np.ndarray:
    """The slots that span the formation's convex hull (scipy's Qhull); every slot for a degenerate (line) formation."""
    if len(slots) < 3:
        return slots
    try:
        return slots[ConvexHull(slots).vertices]
    except Exception:  # noqa: BLE001 - Qhull refuses collinear points: then the end points span the hull
        d = slots - slots.mean(axis=0)
        axis = np.linalg.svd(d, full_matrices=False)[2][0]
        proj = d @ axis
        return slots[[int(proj.argmin()), int(proj.argmax())]]


def footprint_area(slots: np.ndarray, radius: float) -> float:
    """Area of the formation's convex hull dilated by the robot radius (Steiner: A + perimeter x r + pi r^2): the size
    V_min a template needs (Zhu Section IV-B), non-zero for a line."""
    hull = hull_vertices(slots)
    if len(hull) >= 3:
        ordered = slots[ConvexHull(slots).vertices]  # counter-clockwise
        perimeter = float(np.linalg.norm(np.roll(ordered, -1, axis=0) - ordered, axis=1).sum())
        return polygon_area(ordered) + perimeter * radius + math.pi * radius**2
    length = float(np.linalg.norm(hull[-1] - hull[0])) if len(hull) == 2 else 0.0
    return 2.0 * length * radius + math.pi * radius**2


def fit_centres(region: Region, hulls: list[np.ndarray], target: np.ndarray) -> list[np.ndarray | None]:
    """For each candidate formation (its hull slots relative to its centre), the centre nearest `target` such that
    every hull slot lies in `region` (then every slot does, by convexity); None where it fits nowhere. Zhu Section III
    / [20]: the target formation is computed inside the common obstacle-free region.

    c + v in P for every hull slot v  <=>  normals @ c <= offsets - max_v normals @ v: a small projection problem,
    solved exactly by enumerating its candidates (the target, its projections on every line, every crossing)."""
    if region.empty:
        return [None] * len(hulls)
    nrm = region.normals
    starts = np.cumsum([0] + [len(h) for h in hulls[:-1]])
    off = region.offsets - np.maximum.reduceat(np.concatenate(hulls) @ nrm.T, starts, axis=0)  # (B, m)
    target = np.asarray(target, float)
    i, j = _pairs(len(nrm))
    det = nrm[i, 0] * nrm[j, 1] - nrm[i, 1] * nrm[j, 0]
    ok = np.abs(det) > 1e-12
    i, j, det = i[ok], j[ok], det[ok]
    cross = np.stack(
        [(off[:, i] * nrm[j, 1] - off[:, j] * nrm[i, 1]) / det, (nrm[i, 0] * off[:, j] - nrm[j, 0] * off[:, i]) / det],
        axis=-1,
    )  # (B, P, 2)
    proj = target - ((nrm @ target)[None] - off)[..., None] * nrm[None]  # (B, m, 2), normals are unit
    cand = np.concatenate([np.broadcast_to(target, (len(hulls), 1, 2)), proj, cross], axis=1)
    feasible = (cand @ nrm.T <= off[:, None, :] + 1e-7).all(axis=-1)
    dist = np.where(feasible, np.linalg.norm(cand - target, axis=-1), np.inf)
    best = dist.argmin(axis=1)
    return [cand[b, best[b]] if np.isfinite(dist[b, best[b]]) else None for b in range(len(hulls))]
