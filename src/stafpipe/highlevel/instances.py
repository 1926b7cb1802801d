"""The synthetic formation instances that train STAF's high level (the table `stafpipe generate` writes).

STAF Appendix C: "given a robot team formation, we randomly generate the positions of the robots within the formation.
In total, we collect 10,000 data instances". Each instance is one team: a formation type and size, its slots scaled,
rotated and moved, Gaussian noise on each robot, the same formation placed at a goal ahead, and the width of the
narrowest passage ahead. The table schema is documented in docs/data.md.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from stafpipe.config.schema import DataConfig, FormationConfig
from stafpipe.formations import formation_slots, place
from stafpipe.progress import progress

COLUMNS: dict[str, str] = {
    "instance": "int32",
    "formation": "string",
    "n": "int16",
    "robot": "int16",
    "x": "float64",
    "y": "float64",
    "goal_x": "float64",
    "goal_y": "float64",
    "slot_x": "float64",
    "slot_y": "float64",
    "spacing": "float64",
    "heading_deg": "float64",
    "corridor_width": "float64",
}


def generate_instances(data: DataConfig, formation: FormationConfig, seed: int) -> pd.DataFrame:
    """The dataset as a tidy table, one row per robot (columns: COLUMNS). Deterministic for `seed`."""
    data.check()
    formation.check()  # generate needs a formation: the `scenario` option (type null) is refused here
    rng = np.random.default_rng(seed)
    kinds = list(data.mix) or [str(formation.type)]
    cache: dict[tuple[str, int], np.ndarray] = {}
    blocks: list[dict[str, np.ndarray]] = []
    for inst in progress(range(data.instances), desc="generate", unit="team"):
        kind = kinds[int(rng.integers(len(kinds)))]
        n = int(rng.integers(data.n_min, data.n_max + 1))
        if (kind, n) not in cache:
            cache[kind, n] = formation_slots(kind, n, 1.0, formation.angle_deg)
        spacing = float(formation.spacing or 1.0) * rng.uniform(1 - data.spacing_jitter, 1 + data.spacing_jitter)
        slots = cache[kind, n] * spacing
        heading = math.radians(rng.uniform(-data.heading_range_deg, data.heading_range_deg))
        centre = rng.uniform(-data.translation, data.translation, size=2)
        start = place(slots, centre, heading) + rng.normal(0.0, data.position_noise, size=(n, 2))
        goal_dir = heading + math.radians(rng.uniform(-data.goal_heading_jitter_deg, data.goal_heading_jitter_deg))
        goal_centre = centre + rng.uniform(data.goal_distance[0], data.goal_distance[1]) * np.array(
            [math.cos(goal_dir), math.sin(goal_dir)]
        )
        goal = place(slots, goal_centre, heading)
        blocks.append(
            {
                "instance": np.full(n, inst),
                "formation": np.full(n, kind, dtype=object),
                "n": np.full(n, n),
                "robot": np.arange(n),
                "x": start[:, 0],
                "y": start[:, 1],
                "goal_x": goal[:, 0],
                "goal_y": goal[:, 1],
                "slot_x": slots[:, 0],
                "slot_y": slots[:, 1],
                "spacing": np.full(n, spacing),
                "heading_deg": np.full(n, math.degrees(heading)),
                "corridor_width": np.full(n, rng.uniform(data.corridor_width[0], data.corridor_width[1])),
            }
        )
    columns = {name: np.concatenate([b[name] for b in blocks]) for name in COLUMNS}
    return pd.DataFrame(columns).astype(COLUMNS)
