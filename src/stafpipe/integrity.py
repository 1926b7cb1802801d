"""Formation integrity epsilon of STAF's CFI metric (STAF, Appendix D), per formation type.

As printed, two of the formulas score a perfect formation badly (circle: 0; line: 1 - 1/(n-1)); we use the evident
intent, a relative deviation from the ideal, and give printed vs used side by side in docs/metrics.md. Every score is
clipped to [0, 1]. Positions are (k, 2); `heading` is the direction the (sub)team faces, in radians.
"""

from __future__ import annotations

import math

import numpy as np

from stafpipe.formations import WEDGE_APEX_DEG, assign_slots, formation_slots, rotation


def _clip(x: float) -> float:
    return float(min(1.0, max(0.0, x)))


def circle_integrities(p: np.ndarray) -> np.ndarray:
    """`circle_integrity` of each of K groups of robots (K, k >= 3, 2), vectorised over the groups."""
    n = p.shape[1]
    c = p - p.mean(axis=1, keepdims=True)
    ring = np.take_along_axis(p, np.argsort(np.arctan2(c[..., 1], c[..., 0]), axis=1)[..., None], axis=1)
    prev, nxt = np.roll(ring, 1, axis=1) - ring, np.roll(ring, -1, axis=1) - ring
    cos = np.einsum("kij,kij->ki", prev, nxt) / np.maximum(
        np.linalg.norm(prev, axis=-1) * np.linalg.norm(nxt, axis=-1), 1e-12
    )
    theta = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    ideal = (n - 2) * 180.0 / n
    return np.clip(1.0 - np.mean(np.abs(theta - ideal), axis=1) / ideal, 0.0, 1.0)


def circle_integrity(p: np.ndarray) -> float:
    """STAF App. D circle, used form: 1 - mean_i |theta_i - theta*| / theta*, theta* = (n - 2) 180 / n, where theta_i
    is the interior angle at robot i of the polygon through the robots ordered around their centroid."""
    if len(p) < 3:
        return 1.0
    return float(circle_integrities(np.asarray(p, float)[None])[0])


def _v_scores(p: np.ndarray, headings: np.ndarray, apex_deg: float) -> np.ndarray:
    """`v_integrity` of K groups of robots `p` (K, k >= 3, 2), each at each of its headings (K, H): (K, H)."""
    n = p.shape[1]
    c = p - p.mean(axis=1, keepdims=True)
    cos, sin = np.cos(headings)[..., None], np.sin(headings)[..., None]
    cx, cy = c[:, None, :, 0], c[:, None, :, 1]
    x, y = cx * cos + cy * sin, -cx * sin + cy * cos  # (K, H, k): x ahead, y left
    order = np.argsort(-x, axis=-1, kind="stable")
    first, second = order[..., :1], order[..., 1:2]

    def at(v: np.ndarray, i: np.ndarray) -> np.ndarray:
        return np.take_along_axis(v, i, axis=-1)[..., 0]

    fx, fy, sx, sy = at(x, first), at(y, first), at(x, second), at(y, second)
    half = math.radians(apex_deg) / 2.0
    gap = np.abs(fy - sy)
    virtual = (n % 2 == 0) & (fx - sx < 0.25 * np.maximum(gap, 1e-9))
    ax = np.where(virtual, (fx + sx) / 2.0 + gap / 2.0 / math.tan(half), fx)
    ay = np.where(virtual, (fy + sy) / 2.0, fy)
    rest = ~((np.arange(n) == first) & ~virtual[..., None])  # the apex robot is not a base robot
    left, right = rest & (y > ay[..., None]), rest & (y <= ay[..., None])
    lb = np.where(left, x, np.inf).argmin(axis=-1)[..., None]
    rb = np.where(right, x, np.inf).argmin(axis=-1)[..., None]
    lx, ly, rx, ry = at(x, lb), at(y, lb), at(x, rb), at(y, rb)
    l_l, l_r, l_b = np.hypot(lx - ax, ly - ay), np.hypot(rx - ax, ry - ay), np.hypot(lx - rx, ly - ry)
    l_m = np.hypot((lx + rx) / 2.0 - ax, (ly + ry) / 2.0 - ay)
    ideal_m = l_b / 2.0 / math.tan(half)
    score = (
        1.0 - 2.0 * np.abs(l_l - l_r) / np.maximum(l_l + l_r, 1e-12) - np.abs(l_m - ideal_m) / np.maximum(ideal_m, 1e-9)
    )
    return np.where(left.any(axis=-1) & right.any(axis=-1), np.clip(score, 0.0, 1.0), 0.0)


def v_integrities(p: np.ndarray, headings: np.ndarray, apex_deg: float = WEDGE_APEX_DEG) -> np.ndarray:
    """`v_integrity` of each of K groups (K, k >= 3, 2) at its heading (K,)."""
    return _v_scores(p, np.asarray(headings, float)[:, None], apex_deg)[:, 0]


def v_integrity(p: np.ndarray, heading: float, apex_deg: float = WEDGE_APEX_DEG) -> float:
    """STAF App. D wedge: 1 - 2|L_l - L_r| / (L_l + L_r) - |2 L_m - L_b| / L_b (as printed, for a 90 degree apex).

    For a V of apex angle a the second term generalises to |L_m - h*| / h* with h* = (L_b / 2) cot(a / 2), which is the
    printed term when a = 90. The apex is the front-most robot; when the two front-most robots stand level (even n),
    the apex is the virtual point ahead of them where the template puts it.
    """
    if len(p) < 3:
        return 1.0
    return float(v_integrities(np.asarray(p, float)[None], np.array([heading]), apex_deg)[0])


def wedge_shape_integrities(p: np.ndarray, apex_deg: float = WEDGE_APEX_DEG) -> np.ndarray:
    """`wedge_shape_integrity` of each of K groups of robots (K, k >= 3, 2), vectorised over the groups."""
    n = p.shape[1]
    c = p - p.mean(axis=1, keepdims=True)
    if n <= 16:
        i, j = np.triu_indices(n, 1)
        axes = np.concatenate([c, (c[:, i] + c[:, j]) / 2.0], axis=1)  # (K, H, 2)
        usable = np.linalg.norm(axes, axis=-1) > 1e-9  # an axis through the centroid itself has no direction
        headings = np.arctan2(axes[..., 1], axes[..., 0])
    else:
        headings = np.broadcast_to(np.radians(np.arange(0.0, 360.0, 5.0)), (len(p), 72))
        usable = np.ones(headings.shape, dtype=bool)
    return np.maximum(np.where(usable, _v_scores(p, headings, apex_deg), -np.inf).max(axis=1), 0.0)


def wedge_shape_integrity(p: np.ndarray, apex_deg: float = WEDGE_APEX_DEG) -> float:
    """STAF App. D wedge judged as a shape, whichever way it faces: the best `v_integrity` over the axes the wedge can
    have (centroid to a robot, the apex; centroid to the midpoint of two robots, the front pair of an even wedge).

    The printed formula names only the triangle's sides, no heading. Judged at the velocity's heading instead, a
    subteam standing in a perfect wedge while drifting at 0.1 m/s scored 0 (docs/metrics.md). Teams above 16 robots
    try 72 headings every 5 degrees instead of all pairs.
    """
    if len(p) < 3:
        return 1.0
    return float(wedge_shape_integrities(np.asarray(p, float)[None], apex_deg)[0])


def line_integrities(p: np.ndarray) -> np.ndarray:
    """`line_integrity` of each of K groups of robots (K, k >= 3, 2), vectorised over the groups."""
    n = p.shape[1]
    c = p - p.mean(axis=1, keepdims=True)
    axis = np.linalg.svd(c, full_matrices=False)[2][:, 0]  # (K, 2) principal axis of each group
    ordered = np.take_along_axis(p, np.argsort(np.einsum("kij,kj->ki", c, axis), axis=1)[..., None], axis=1)
    gaps = np.linalg.norm(np.diff(ordered, axis=1), axis=-1)
    ideal = np.linalg.norm(ordered[:, -1] - ordered[:, 0], axis=-1) / (n - 1)
    score = 1.0 - np.mean(np.abs(gaps - ideal[:, None]), axis=1) / np.maximum(ideal, 1e-9)
    return np.where(ideal < 1e-9, 0.0, np.clip(score, 0.0, 1.0))


def line_integrity(p: np.ndarray) -> float:
    """STAF App. D line, used form: 1 - mean_k |L_{k,k+1} - L/(n-1)| / (L/(n-1)), robots ordered along the line's
    principal axis, L the distance between its two ends: equal gaps on a straight line score 1."""
    if len(p) < 3:
        return 1.0
    return float(line_integrities(np.asarray(p, float)[None])[0])


def shape_integrity(p: np.ndarray, kind: str, spacing: float, heading: float, angle_deg: float = 90.0) -> float:
    """Formations STAF does not score (square, t, v templates of Zhu and Cezayirli) and a fallback: 1 - mean |d_ij -
    d*_ij| / mean d*_ij over robot pairs, robots matched to the template's slots (Hungarian) at the team's heading."""
    n = len(p)
    if n < 3:
        return 1.0
    slots = formation_slots(kind, n, spacing, angle_deg) @ rotation(heading).T + p.mean(axis=0)
    perm = assign_slots(p, slots)
    d = np.linalg.norm(p[:, None] - p[None], axis=-1)
    ds = np.linalg.norm(slots[perm][:, None] - slots[perm][None], axis=-1)
    iu = np.triu_indices(n, 1)
    return _clip(1.0 - float(np.mean(np.abs(d[iu] - ds[iu]))) / float(np.mean(ds[iu])))


def formation_integrities(
    p: np.ndarray, kind: str, spacing: float, headings: np.ndarray, angle_deg: float = 90.0
) -> np.ndarray:
    """`formation_integrity` of each of K groups of the same robots (K, k, 2) facing `headings` (K,), vectorised over
    the groups where the formation's score is (every kind but the template-matched ones)."""
    if p.shape[1] < 3:
        return np.ones(len(p))
    if kind == "circle":
        return circle_integrities(p)
    if kind == "wedge":
        return wedge_shape_integrities(p, WEDGE_APEX_DEG)
    if kind == "v":
        return v_integrities(p, headings, angle_deg)
    if kind == "line":
        return line_integrities(p)
    return np.array([shape_integrity(q, kind, spacing, h, angle_deg) for q, h in zip(p, headings, strict=True)])


def formation_integrity(p: np.ndarray, kind: str, spacing: float, heading: float, angle_deg: float = 90.0) -> float:
    """Epsilon of CFI for robots `p` meant to hold formation `kind`."""
    group = np.asarray(p, float)[None]
    return float(formation_integrities(group, kind, spacing, np.array([heading]), angle_deg)[0])
