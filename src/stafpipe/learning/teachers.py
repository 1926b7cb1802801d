"""Hand-made low levels: the imitation teachers of the warm start (learning/ppo.py:imitate) and, in
`method=staf_planned` (`method.low_level`), the method with its learned low level removed, for the ablation of
docs/staf_planned.md.

- `proportional`: a step towards the target at min(1, gain x distance) of top speed (the step of the residual prior,
  staf_net.proportional_step).
- `avoiding`: the same step, then the classical methods' collision avoidance (controllers/base.py:limit_approach):
  towards a robot or obstacle closer than 0.35 m the approach speed is capped at 2 x (gap - 0.02 m), as in `method=lf`.
- `sliding`: `avoiding`, with the point aimed at first moved off the closest obstacle: where it lies beyond the
  line `SLIDE_MARGIN` in front of that obstacle's surface (seen from the robot), it is moved back onto that line, so a
  robot whose slot lies in a wall runs along the wall at that margin instead of pressing against it (a local formation
  adaptation from what the robot senses: its target and its closest obstacle point). On a differential drive the
  cap is applied a second time, to the motion the drive will make (forward along the heading, at the command's speed
  times cos(heading error), drives.py): a robot turning round towards its aim drives along its heading meanwhile,
  and two neighbours turning round the opposite ways drove into each other (measured: seed-777 map 1, a line of 8
  whose start noise put two robots 0.34 m apart; the command pointed away from the neighbour, the heading at it).
- `capped`: `avoiding` with `sliding`'s second cap on a differential drive (on the motion the drive makes), without
  moving the aim off the wall: on holonomic robots it is `avoiding` itself.
- `orca`: the same step as the preferred velocity of ORCA (controllers/orca.py; van den Berg et al., ISRR 2011) with
  `method=zhu`'s settings (horizon 1 s, margin 0.1 m, recovery 0.1 s): reciprocal avoidance of every sensed robot and
  the nearest obstacle point.
"""

from __future__ import annotations

import numpy as np

from stafpipe.controllers.base import STOP_GAP, forward_capped, limit_approach
from stafpipe.controllers.lf import LFConfig
from stafpipe.controllers.orca import ORCA_HORIZON, ORCA_MARGIN, ORCA_RECOVERY, orca_velocities
from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.learning.features import to_robot_frame
from stafpipe.sensing import Observation

TEACHERS = ("proportional", "avoiding", "sliding", "capped", "orca")
SLIDE_MARGIN = PlanConfig().margin
"""m between a robot's surface and the closest obstacle that the `sliding` teacher's aim keeps: the plan's default
`margin` between a formation's outer robots and the walls (0.15 m)."""
_LF = LFConfig()  # the teachers avoid as method=lf's cap and method=zhu's ORCA do by default
AVOID_DISTANCE, AVOID_GAIN = _LF.avoid_distance, _LF.avoid_gain


def check_low_level(low_level: str, gain: float, key: str, stop_gap: float = STOP_GAP) -> None:
    """A learned method's `low_level` (`learned` or a teacher here), its `proportional_gain` and `stop_gap`, named
    under `key`."""
    from stafpipe.errors import require

    require(
        low_level in ("learned", *TEACHERS), f"{key}.low_level", f"must be one of {['learned', *TEACHERS]}", low_level
    )
    require(gain > 0, f"{key}.proportional_gain", "must be > 0", gain)
    check_stop_gap(stop_gap, f"{key}.stop_gap")


def check_stop_gap(stop_gap: float, key: str) -> None:
    """A teacher's stop gap: at least 0 and short of where its braking starts (AVOID_DISTANCE), or it never moves."""
    from stafpipe.errors import require

    require(0.0 <= stop_gap < AVOID_DISTANCE, key, f"must be in [0, {AVOID_DISTANCE})", stop_gap)


NEAR_WALL_GAP = AVOID_DISTANCE + 0.05
"""m: the synthetic wall points of `near_wall_copy` lie 0 to this far from the robot's surface (a little beyond where
the `avoiding` teacher starts to brake)."""


def _near_offsets(reach: float, shape: tuple[int, ...], rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Gaps (shape) uniform in [0, `NEAR_WALL_GAP`] and offsets (shape + (2,)) of length `reach` + gap at a uniform
    bearing: where the copies put a wall point (reach: the radius) or a neighbour's centre (reach: 2 radii)."""
    gap = rng.uniform(0.0, NEAR_WALL_GAP, shape)
    bearing = rng.uniform(-np.pi, np.pi, shape)
    return gap, (reach + gap)[..., None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=-1)


def near_wall_copy(obs: Observation, radius: float, rng: np.random.Generator) -> Observation:
    """`obs` with every robot's closest obstacle point replaced by one at a uniform bearing, 0 to `NEAR_WALL_GAP`
    from its surface: states in which the teacher brakes for a wall ahead, beside or behind, which the training maps
    hold too few of for the network to learn the braking (docs/staf_planned.md)."""
    gap, vec = _near_offsets(radius, obs.obstacle_distance.shape, rng)
    return obs._replace(obstacle=vec, obstacle_distance=gap)


def near_neighbour_copy(obs: Observation, radius: float, rng: np.random.Generator) -> Observation:
    """`obs` with each robot's nearest sensed neighbour seen at a uniform bearing, 0 to `NEAR_WALL_GAP` from its
    surface (only in that robot's own view, which is all its action depends on): states in which the teacher brakes
    for a neighbour closing in from any side."""
    rel = obs.rel_position.copy()
    n = rel.shape[-2]
    dist = np.where(obs.neighbours & ~np.eye(n, dtype=bool), np.linalg.norm(rel, axis=-1), np.inf)
    nearest = dist.argmin(-1)
    has = np.isfinite(dist.min(-1))
    _, vec = _near_offsets(2 * radius, has.shape, rng)
    lead = np.indices(has.shape)
    rel[(*(x[has] for x in lead), nearest[has])] = vec[has]
    return obs._replace(rel_position=rel)


def teacher_actions(
    kind: str,
    to_aim: np.ndarray,
    obs: Observation,
    radius: float,
    max_speed: float,
    gain: float,
    drive: str,
    stop_gap: float = STOP_GAP,
) -> np.ndarray:
    """(B, n, 2) actions in the policies' action space (robot frame, in units of top speed) towards the world-frame
    vectors `to_aim` (B, n, 2) from each robot to the point it should reach, for the batched observation `obs` of
    robots with this `drive` (scenario robot.drive). `stop_gap`: the gap (m) the approach cap brakes to (the classical
    methods' 0.02 m by default; a larger one keeps an imitator's own errors short of contact, docs/staf_planned.md)."""
    if kind == "sliding":
        to_aim = off_the_wall(to_aim, obs)
    length = np.linalg.norm(to_aim, axis=-1, keepdims=True)
    world = max_speed * gain * to_aim / np.maximum(1.0, gain * length)  # min(1, gain x distance) of top speed
    if kind in ("avoiding", "sliding", "capped"):
        world = limit_approach(world, obs, radius, AVOID_DISTANCE, AVOID_GAIN, stop_gap)  # every world at once
        if kind in ("sliding", "capped") and drive == "diff_drive":
            world = forward_capped(world, obs, radius, AVOID_DISTANCE, AVOID_GAIN, stop_gap)
    elif kind == "orca":
        world = np.stack(
            [
                orca_velocities(world[w], obs.world(w), radius, max_speed, ORCA_HORIZON, ORCA_RECOVERY, ORCA_MARGIN)
                for w in range(len(world))
            ]
        )
    return to_robot_frame(world, np.cos(obs.heading), np.sin(obs.heading)) / max_speed


def off_the_wall(to_aim: np.ndarray, obs: Observation) -> np.ndarray:
    """`to_aim` (.., n, 2) with each aimed point no further towards the robot's closest obstacle point than
    `SLIDE_MARGIN` short of where its surface would touch it (the `sliding` teacher)."""
    unit = obs.obstacle / np.maximum(np.linalg.norm(obs.obstacle, axis=-1, keepdims=True), 1e-9)
    room = obs.obstacle_distance - SLIDE_MARGIN  # how far the robot may move towards the obstacle
    excess = np.maximum((to_aim * unit).sum(-1) - room, 0.0)
    return to_aim - excess[..., None] * unit
