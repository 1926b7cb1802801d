"""Formation integrity epsilon of STAF's CFI metric (000_f89c49495043d27c.txt, Appendix D), per formation type.

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


def circle_integrity(p: np.ndarray) -> float:
    """STAF App. D circle, used form: 1 - mean_i |theta_i - theta*| / theta*, theta* = (n - 2) 180 / n, where theta_i
    is the interior angle at robot i of the polygon through the robots ordered around their centroid."""
    n = len(p)
    if n < 3:
        return 1.0
    c = p - p.mean(axis=0)
    ring = p[np.argsort(np.arctan2(c[:, 1], c[:, 0]))]
    prev, nxt = np.roll(ring, 1, axis=0) - ring, np.roll(ring, -1, axis=0) - ring
    cos = np.einsum("ij,ij->i", prev, nxt) / np.maximum(np.linalg.norm(prev, axis=1) * np.linalg.norm(nxt, axis=1), 1e-12)
    theta = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    ideal = (n - 2) * 180.0 / n
    return _clip(1.0 - float(np.mean(np.abs(theta - ideal))) / ideal)


def v_integrity(p: np.ndarray, heading: float, apex_deg: float = WEDGE_APEX_DEG) -> float:
    """STAF App. D wedge: 1 - 2|L_l - L_r| / (L_l + L_r) - |2 L_m - L_b| / L_b (as printed, for a 90 degree apex).

    For a V of apex angle a the second term generalises to |L_m - h*| / h* with h* = (L_b / 2) cot(a / 2), which is the
    printed term when a = 90. The apex is the front-most robot; when the two front-most robots stand level (even n),
    the apex is the virtual point ahead of them where the template puts it.
    """
    n = len(p)
    if n < 3:
        return 1.0
    local = (p - p.mean(axis=0)) @ rotation(heading)  # x ahead, y left
    order = np.argsort(-local[:, 0])
    half = math.radians(apex_deg) / 2.0
    first, second = local[order[0]], local[order[1]]
    gap = abs(first[1] - second[1])
    if n % 2 == 0 and first[0] - second[0] < 0.25 * max(gap, 1e-9):
        mid = (first + second) / 2.0
        apex = mid + np.array([gap / 2.0 / math.tan(half), 0.0])
        rest = local
    else:
        apex = first
        rest = np.delete(local, order[0], axis=0)
    left, right = rest[rest[:, 1] > apex[1]], rest[rest[:, 1] <= apex[1]]
    if len(left) == 0 or len(right) == 0:
        return 0.0
    lb, rb = left[left[:, 0].argmin()], right[right[:, 0].argmin()]
    l_l, l_r, l_b = np.linalg.norm(lb - apex), np.linalg.norm(rb - apex), np.linalg.norm(lb - rb)
    l_m = np.linalg.norm((lb + rb) / 2.0 - apex)
    ideal_m = l_b / 2.0 / math.tan(half)
    return _clip(1.0 - 2.0 * abs(l_l - l_r) / (l_l + l_r) - abs(l_m - ideal_m) / max(ideal_m, 1e-9))


def line_integrity(p: np.ndarray) -> float:
    """STAF App. D line, used form: 1 - mean_k |L_{k,k+1} - L/(n-1)| / (L/(n-1)), robots ordered along the line's
    principal axis, L the distance between its two ends: equal gaps on a straight line score 1."""
    n = len(p)
    if n < 3:
        return 1.0
    c = p - p.mean(axis=0)
    axis = np.linalg.svd(c, full_matrices=False)[2][0]
    ordered = p[np.argsort(c @ axis)]
    gaps = np.linalg.norm(np.diff(ordered, axis=0), axis=1)
    ideal = np.linalg.norm(ordered[-1] - ordered[0]) / (n - 1)
    if ideal < 1e-9:
        return 0.0
    return _clip(1.0 - float(np.mean(np.abs(gaps - ideal))) / ideal)


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


def formation_integrity(p: np.ndarray, kind: str, spacing: float, heading: float, angle_deg: float = 90.0) -> float:
    """Epsilon of CFI for robots `p` meant to hold formation `kind`."""
    if kind == "circle":
        return circle_integrity(p)
    if kind == "wedge":
        return v_integrity(p, heading, WEDGE_APEX_DEG)
    if kind == "v":
        return v_integrity(p, heading, angle_deg)
    if kind == "line":
        return line_integrity(p)
    return shape_integrity(p, kind, spacing, heading, angle_deg)
