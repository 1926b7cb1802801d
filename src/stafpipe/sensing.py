"""What a method may see, per robot, computed vectorized over (worlds, robots).

Per robot: position, velocity, heading, goal, the vector to the closest obstacle point (STAF's c_i), and neighbours
within the sensing/communication radius (STAF Appendix C: 2 m) with their relative positions and velocities. Optional
imperfections: Gaussian position noise (STAF Appendix F), bounded range and bearing errors and occlusion by other
robots (Cezayirli & Kerestecioglu, Section II: a partially occluded robot counts as occluded), and dropped messages
(Zhu et al. 2019, Section V communication faults).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


@dataclass
class SensingConfig:
    """Sensing and communication (group-free section `sensing`)."""

    radius: float = 2.0
    """Neighbour sensing / communication radius in metres (STAF Appendix C: 2 m)."""
    position_noise: float = 0.02
    """Standard deviation (m) of Gaussian noise on each robot's own position estimate (STAF Appendix F), drawn anew
    every step: 2 cm by default, a localisation error of an indoor robot (the papers give none; docs/decisions.md)."""
    range_error: float = 0.0
    """Bound of the uniform error on a neighbour's measured range (Cezayirli's Delta r)."""
    bearing_error_deg: float = 0.0
    """Bound of the uniform error on a neighbour's measured bearing (Cezayirli's Delta theta)."""
    occlusion: bool = False
    """Robots hide the robots behind them (Cezayirli Section II)."""
    drop_prob: float = 0.0
    """Probability that a robot misses a neighbour in a control step (a detection dropout: neither sensed nor heard,
    STAF Fig. 14's noise study). Lost messages alone (the neighbour still sensed) are the world's `drop` fault
    (`world.faults`, docs/faults.md)."""

    def check(self, key: str = "sensing") -> None:
        from stafpipe.errors import require

        require(self.radius > 0, f"{key}.radius", "must be > 0", self.radius)
        for name in ("position_noise", "range_error", "bearing_error_deg"):
            require(getattr(self, name) >= 0, f"{key}.{name}", "must be >= 0", getattr(self, name))
        require(0 <= self.drop_prob <= 1, f"{key}.drop_prob", "must be in [0, 1]", self.drop_prob)


class Observation(NamedTuple):
    """Observations of every robot; leading axes (worlds, robots) in a batch, (robots,) for one world."""

    position: np.ndarray
    """(.., n, 2) own position estimate."""
    velocity: np.ndarray
    """(.., n, 2) own velocity."""
    heading: np.ndarray
    """(.., n) own heading, rad."""
    goal: np.ndarray
    """(.., n, 2) own goal."""
    obstacle: np.ndarray
    """(.., n, 2) vector from the robot's centre to the closest obstacle point (STAF's c_i)."""
    obstacle_distance: np.ndarray
    """(.., n) distance from the robot's surface to the closest obstacle."""
    neighbours: np.ndarray
    """(.., n, n) bool, [i, j]: robot i senses robot j (within range; occlusion, noise and sensing.drop_prob
    applied)."""
    rel_position: np.ndarray
    """(.., n, n, 2) [i, j]: measured position of j relative to i (valid where neighbours)."""
    rel_velocity: np.ndarray
    """(.., n, n, 2) [i, j]: velocity of j minus that of i."""
    time: np.ndarray
    """(..,) seconds since the episode started."""
    movers: np.ndarray
    """(.., M, 4) moving obstacles: x, y, vx, vy (a walking human tracked by motion capture, Zhu et al. 2019 Section
    V-B); padding rows of a batch are far away and still."""
    heard: np.ndarray
    """(.., n, n) bool, [i, j]: robot i receives robot j's messages: the sensed neighbours, less what the world's
    `silent` and `drop` faults take away (stafpipe.faults). What communicating methods use as their graph."""

    def world(self, b: int) -> Observation:
        """The observation of world `b` of a batch."""
        return Observation(*(x[b] for x in self))


def occluded(rel: np.ndarray, dist: np.ndarray, radius: float) -> np.ndarray:
    """(.., n, n) bool, [i, j]: some robot k nearer to i than j covers part of j's silhouette seen from i."""
    ang = np.arctan2(rel[..., 1], rel[..., 0])
    half = np.arcsin(np.clip(radius / np.maximum(dist, radius), 0.0, 1.0))
    gap = np.abs((ang[..., :, :, None] - ang[..., :, None, :] + np.pi) % (2 * np.pi) - np.pi)  # [i, j, k]
    overlap = gap < half[..., :, :, None] + half[..., :, None, :]
    nearer = dist[..., :, None, :] < dist[..., :, :, None]
    not_self = ~np.eye(rel.shape[-2], dtype=bool)
    blocks = overlap & nearer & not_self[:, None, :] & not_self[None, :, :]  # k differs from i and from j
    return blocks.any(axis=-1)


def observe(
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    goal: np.ndarray,
    time: np.ndarray,
    seg_a: np.ndarray,
    seg_b: np.ndarray,
    seg_r: np.ndarray,
    robot_radius: float,
    cfg: SensingConfig,
    rngs: list[np.random.Generator],
    movers: np.ndarray | None = None,
) -> Observation:
    """Observations of B worlds: pos, vel, goal (B, n, 2); obstacles as capsules seg_a, seg_b (B, C, 2), seg_r (B,
    C)."""
    # Closest point of every capsule spine, per coordinate: (B, n, C) arrays, no (.., 2) axis (this runs every step).
    px, py = pos[..., 0, None], pos[..., 1, None]
    ax, ay = seg_a[..., None, :, 0], seg_a[..., None, :, 1]
    abx, aby = seg_b[..., None, :, 0] - ax, seg_b[..., None, :, 1] - ay
    t = np.clip(((px - ax) * abx + (py - ay) * aby) / np.maximum(abx * abx + aby * aby, 1e-12), 0.0, 1.0)
    dx, dy = ax + t * abx - px, ay + t * aby - py
    spine = np.sqrt(dx * dx + dy * dy)
    surfaces = spine - seg_r[..., None, :]
    k = surfaces.argmin(axis=-1)[..., None]
    dist_c = np.take_along_axis(spine, k, axis=-1)[..., 0]
    surface = np.take_along_axis(surfaces, k, axis=-1)[..., 0]
    # The obstacle vector points at the capsule's surface, not its spine.
    scale = np.maximum(surface, 0.0) / np.maximum(dist_c, 1e-12)
    obstacle = np.stack(
        [np.take_along_axis(dx, k, axis=-1)[..., 0], np.take_along_axis(dy, k, axis=-1)[..., 0]], axis=-1
    )
    obstacle *= scale[..., None]
    obstacle_distance = surface - robot_radius

    rel = pos[..., None, :, :] - pos[..., :, None, :]  # [i, j] = p_j - p_i
    dist = np.sqrt(np.einsum("...i,...i->...", rel, rel))
    mask = dist <= cfg.radius
    idx = np.arange(pos.shape[-2])
    mask[..., idx, idx] = False
    if cfg.occlusion:
        mask &= ~occluded(rel, dist, robot_radius)
    own = pos
    measured = rel
    if cfg.position_noise > 0 or cfg.range_error > 0 or cfg.bearing_error_deg > 0 or cfg.drop_prob > 0:
        own = pos + np.stack([r.normal(0.0, cfg.position_noise, pos.shape[1:]) for r in rngs])
        dr = np.stack([r.uniform(-cfg.range_error, cfg.range_error, dist.shape[1:]) for r in rngs])
        db = np.radians(cfg.bearing_error_deg) * np.stack([r.uniform(-1, 1, dist.shape[1:]) for r in rngs])
        bearing = np.arctan2(rel[..., 1], rel[..., 0]) + db
        rng_m = np.maximum(dist + dr, 0.0)
        measured = rng_m[..., None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=-1)
        if cfg.drop_prob > 0:
            mask &= np.stack([r.random(dist.shape[1:]) >= cfg.drop_prob for r in rngs])
    rel_vel = vel[..., None, :, :] - vel[..., :, None, :]
    movers = np.zeros((pos.shape[0], 0, 4)) if movers is None else movers
    return Observation(
        own, vel, heading, goal, obstacle, obstacle_distance, mask, measured, rel_vel, time, movers, mask.copy()
    )
