"""The adaptation series (adaptation.py): a subteam's scale and type integrity, known answers, and the plot kind."""

from __future__ import annotations

import numpy as np

from stafpipe.adaptation import adaptation_series
from stafpipe.formations import formation_slots
from stafpipe.metrics import MetricContext


def test_a_line_at_half_its_spacing_has_scale_one_half_and_keeps_its_type() -> None:
    ctx = MetricContext(0.2, "line", 1.0, 90.0, 0.0, 2.4, 0.0)
    line = formation_slots("line", 3, 1.0)  # across the heading (x), as the team stands
    bent = line.copy()
    bent[1] += [0.8, 0.0]  # the middle robot 0.8 m ahead of its mates: a line no more
    positions = np.stack([np.vstack([0.5 * line, 2.0 * line + [5, 0]]), np.vstack([bent, bent + [5, 0]])])
    subteams = np.array([[0, 0, 0, 1, 1, 1]] * 2)
    velocities = np.zeros_like(positions)
    out = adaptation_series(np.array([0.0, 0.1]), positions, velocities, subteams, ctx)
    first = out[out.time == 0.0].set_index("subteam")
    assert np.allclose(first.scale, [0.5, 2.0])
    assert np.all(first.integrity > 0.99)
    assert np.all(out[out.time == 0.1].integrity < 0.8)  # 0.72 (integrity.line_integrities)
    assert not out.in_passage.any()  # no passage known to the context
