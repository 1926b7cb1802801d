"""Distances from points to static obstacles given as plain parts (capsules, solid polygons, an occupancy grid): what
scenario.py checks a team's placement with, and what geometry.py builds a scenario's clearance on. It knows no
scenario, so the scenario module below it and the geometry above it both import it, never each other both ways."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib.path import Path as MplPath


def capsule_parts(capsules: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Capsules (each with `a`, `b`, `radius`) as arrays: segment starts (C, 2), ends (C, 2), radii (C,)."""
    a = np.array([c.a for c in capsules], dtype=float)
    b = np.array([c.b for c in capsules], dtype=float)
    r = np.array([c.radius for c in capsules], dtype=float)
    return a, b, r


def closest_points(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Closest point on each segment a-b to each point p: p (..., P, 2), a and b (..., C, 2) -> (..., P, C, 2)."""
    ab = b - a
    denom = np.maximum(np.einsum("...ci,...ci->...c", ab, ab), 1e-12)
    ap = p[..., :, None, :] - a[..., None, :, :]
    t = np.clip(np.einsum("...pci,...ci->...pc", ap, ab) / denom[..., None, :], 0.0, 1.0)
    return a[..., None, :, :] + t[..., None] * ab[..., None, :, :]


def distance_to(
    points: np.ndarray, capsules: Sequence[Any], polygons: Sequence[np.ndarray], occupancy: Any
) -> np.ndarray:
    """Distance (P,) from each point to the nearest obstacle surface; 0 inside a solid polygon or an occupied cell of
    `occupancy` (an OccupancyGrid, or None)."""
    a, b, r = capsule_parts(capsules)
    d = np.full(len(points), np.inf)
    for start in range(0, len(points), 20_000):  # chunks keep the (P, C, 2) temporary small
        chunk = points[start : start + 20_000]
        cp = closest_points(chunk, a, b)
        d[start : start + 20_000] = (np.linalg.norm(chunk[:, None, :] - cp, axis=-1) - r).min(axis=1)
    return inside_is_zero(d, points, polygons, occupancy)


def inside_is_zero(d: np.ndarray, points: np.ndarray, polygons: Sequence[np.ndarray], occupancy: Any) -> np.ndarray:
    """Distances (P,) to the capsules, 0 where a point lies inside a solid polygon or an occupied map cell."""
    for poly in polygons:
        d[MplPath(poly).contains_points(points)] = 0.0
    if occupancy is not None:  # inside a wall of a ROS map: its cells, not its outline, say so
        d[occupancy.contains(points)] = 0.0
    return np.maximum(d, 0.0)
