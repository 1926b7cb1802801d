"""How a subteam's formation adapts over an episode, from its log (`stafpipe plot adaptation`): per sample and
subteam, its scale (the mean distance between its robots over that of its formation at the scenario's spacing:
below 1 it has shrunk, above 1 stretched) and its type integrity (CFI's epsilon, integrity.py), and whether it is in
a passage. What a figure shows of a wedge compressing in the corridor and opening after it."""

from __future__ import annotations

import numpy as np
import pandas as pd

from stafpipe.formations import formation_slots
from stafpipe.integrity import formation_integrities
from stafpipe.metrics import MetricContext, in_passage


def mean_gap(p: np.ndarray) -> np.ndarray:
    """(K,) the mean distance between the k robots of each of K groups (K, k, 2)."""
    k = p.shape[1]
    d = np.linalg.norm(p[:, :, None] - p[:, None], axis=-1)
    return d.sum(axis=(1, 2)) / (k * (k - 1))


def adaptation_series(
    time: np.ndarray, positions: np.ndarray, velocities: np.ndarray, subteams: np.ndarray, ctx: MetricContext
) -> pd.DataFrame:
    """Rows (time, subteam, robots, scale, integrity, in_passage) for every sample and subteam of two or more
    robots; `positions`, `velocities` (T, n, 2), `subteams` (T, n)."""
    inside = in_passage(positions, ctx)
    rows: list[pd.DataFrame] = []
    for labels in np.unique(subteams, axis=0):  # samples with the same subteams, one group at a time
        ks = np.flatnonzero((subteams == labels).all(axis=1))
        for team in np.unique(labels):
            idx = np.flatnonzero(labels == team)
            if len(idx) < 2:
                continue
            p = positions[ks][:, idx]
            nominal = mean_gap(formation_slots(ctx.formation, len(idx), ctx.spacing, ctx.angle_deg)[None])[0]
            v = velocities[ks][:, idx].mean(axis=1)
            moving = np.linalg.norm(v, axis=-1) > 0.05
            heading = np.where(moving, np.arctan2(v[:, 1], v[:, 0]), np.radians(ctx.heading_deg))
            eps = formation_integrities(p, ctx.formation, ctx.spacing, heading, ctx.angle_deg)
            rows.append(
                pd.DataFrame(
                    {
                        "time": time[ks],
                        "subteam": int(team),
                        "robots": len(idx),
                        "scale": mean_gap(p) / nominal,
                        "integrity": eps,
                        "in_passage": inside[ks][:, idx].any(axis=1),
                    }
                )
            )
    columns = ["time", "subteam", "robots", "scale", "integrity", "in_passage"]
    out = pd.concat(rows) if rows else pd.DataFrame(columns=columns)
    return out.sort_values(["time", "subteam"], kind="stable").reset_index(drop=True)
