"""Formation templates (slots) for any team size, and robot-to-slot assignment.

Frame convention: a formation's slots are given in its own frame, x pointing where the formation heads and y to its
left, with the centroid at the origin. `place` rotates them to a heading and moves them to a centre.

- circle, wedge, line: STAF (Section 4 and Appendix D). The line is abreast, i.e.
  perpendicular to the heading: it is the formation whose width forces a split in a corridor (STAF Section 4, 9 robots
  in line split into three subteams). The wedge is a V whose apex angle is 90 degrees: STAF Appendix D scores a wedge by
  |2 L_m - L_b| / L_b, which is zero exactly when the altitude is half the base, i.e. a right angle at the apex.
- square, t: Zhu, Juhl, Ferranti and Alonso-Mora, ICRA 2019 (Section VI, square and T templates; 4x4 grids of 16
  robots).
- v with any apex angle: Cezayirli and Kerestecioglu, "A Non-Communicating Multi-Robot System with Switchable
  Formations" (simulation 2, a 120 degree V).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

FORMATION_TYPES: tuple[str, ...] = ("circle", "wedge", "line", "square", "t", "v")
WEDGE_APEX_DEG = 90.0


def _circle(n: int, s: float) -> np.ndarray:
    # Regular n-gon whose neighbouring slots are s apart: chord 2 R sin(pi / n) = s.
    radius = s / (2.0 * math.sin(math.pi / n))
    theta = 2.0 * math.pi * np.arange(n) / n
    return radius * np.stack([np.cos(theta), np.sin(theta)], axis=1)


def _line(n: int, s: float) -> np.ndarray:
    y = ((n - 1) / 2.0 - np.arange(n)) * s
    return np.stack([np.zeros(n), y], axis=1)


def _v(n: int, s: float, apex_deg: float) -> np.ndarray:
    half = math.radians(apex_deg) / 2.0
    if n % 2:  # a robot at the apex, then pairs s, 2s, ... behind it along the two arms
        dist = np.concatenate([[0.0], np.repeat(np.arange(1, (n - 1) // 2 + 1) * s, 2)])
        side = np.concatenate([[0.0], np.tile([1.0, -1.0], (n - 1) // 2)])
    else:  # no robot at the apex: the first pair stands s apart, the apex is a virtual point ahead of it
        first = s / (2.0 * math.sin(half))
        dist = np.repeat(first + np.arange(n // 2) * s, 2)
        side = np.tile([1.0, -1.0], n // 2)
    return np.stack([-dist * math.cos(half), side * dist * math.sin(half)], axis=1)


def _square(n: int, s: float) -> np.ndarray:
    cols = math.ceil(math.sqrt(n))
    pts = []
    for k in range(n):
        row, col = divmod(k, cols)
        in_row = min(cols, n - row * cols)
        pts.append((-row * s, ((in_row - 1) / 2.0 - col) * s))
    return np.asarray(pts, dtype=float)


def _t(n: int, s: float) -> np.ndarray:
    bar = math.ceil((n + 1) / 2)
    stem = n - bar
    top = _line(bar, s)
    below = np.stack([-s * np.arange(1, stem + 1), np.zeros(stem)], axis=1)
    return np.concatenate([top, below])


def formation_slots(kind: str, n: int, spacing: float, angle_deg: float = WEDGE_APEX_DEG) -> np.ndarray:
    """Slots (n, 2) of formation `kind` for n robots, neighbouring slots `spacing` apart, centroid at the origin.

    `angle_deg` is the apex angle of the `v` formation (the wedge is fixed at 90 degrees).
    """
    if kind not in FORMATION_TYPES:
        raise ValueError(f"unknown formation type '{kind}'; known: {', '.join(FORMATION_TYPES)}")
    if n < 2:
        raise ValueError(f"a formation needs at least 2 robots, got n={n}")
    if spacing <= 0:
        raise ValueError(f"formation spacing must be > 0, got {spacing}")
    if kind == "circle":
        pts = _circle(n, spacing)
    elif kind == "line":
        pts = _line(n, spacing)
    elif kind == "wedge":
        pts = _v(n, spacing, WEDGE_APEX_DEG)
    elif kind == "v":
        if not 0.0 < angle_deg < 180.0:
            raise ValueError(f"v formation apex angle must be in (0, 180) degrees, got {angle_deg}")
        pts = _v(n, spacing, angle_deg)
    elif kind == "square":
        pts = _square(n, spacing)
    else:
        pts = _t(n, spacing)
    return pts - pts.mean(axis=0)


def rotation(heading_rad: float) -> np.ndarray:
    """2x2 rotation matrix by `heading_rad`."""
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    return np.array([[c, -s], [s, c]])


def place(slots: np.ndarray, centre: np.ndarray | tuple[float, float], heading_rad: float | np.ndarray) -> np.ndarray:
    """World positions of formation-frame `slots` rotated to `heading_rad` (a number or a 0-d array) and moved to
    `centre`."""
    return slots @ rotation(float(heading_rad)).T + np.asarray(centre, dtype=float)


def assign_slots(positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Slot index for each robot minimising the total squared travel distance (Hungarian method).

    Returns `perm` with `targets[perm[i]]` the slot of robot i.
    """
    positions, targets = np.asarray(positions, float), np.asarray(targets, float)
    if positions.shape[1] == 2:  # cdist's values (dx^2 + dy^2) without its wrapper: STAF's split assigns every subteam
        gap = positions[:, None] - targets[None]  # within a control step (benchmarks/staf_decision_time.py); a test
        cost = (gap * gap).sum(axis=-1)
    else:
        cost = cdist(positions, targets, "sqeuclidean")
    rows, cols = linear_sum_assignment(cost)
    perm = np.empty(len(rows), dtype=int)
    perm[rows] = cols
    return perm
