"""What a learned policy sees, per robot in its own frame (rotated by its heading), from the harness' Observation.

Own features (7): target vector (clipped), own velocity, vector to the closest obstacle point (STAF's c_i) and its
distance. Edge features (5) for each neighbour j within the communication radius: its relative position, relative
velocity and distance. The target is the robot's own goal, or (`guide=path`) a point `lookahead` metres ahead on the
team centre's shortest path on the map (the harness' global planner, TeamInfo.path) until the robot is within
`release` metres of the path's end, then its own goal: a straight goal vector leaves robots stuck on the wall beside a
gap (we saw it in the first DGNN runs).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from stafpipe.geometry import point_ahead
from stafpipe.sensing import Observation

OWN, EDGE = 7, 5


class Features(NamedTuple):
    own: np.ndarray
    """(.., n, 7)"""
    edge: np.ndarray
    """(.., n, n, 5) [i, j]: what i knows of neighbour j."""
    mask: np.ndarray
    """(.., n, n) bool: j is i's neighbour."""


def _rotate(v: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Express world-frame vectors v (.., 2) in frames of heading (cos c, sin s): R(-heading) v."""
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)


def guide_targets(pos: np.ndarray, goal: np.ndarray, path: np.ndarray, lookahead: float, release: float) -> np.ndarray:
    """(n, 2) targets of one world's robots: the point `lookahead` ahead of each robot's projection on `path` (K, 2),
    or the robot's own goal once its projection is within `release` of the path's end."""
    point, _, left = point_ahead(path, pos, lookahead)
    return np.where((left < release)[:, None], goal, point)


def features(obs: Observation, goal_clip: float, sensing_radius: float, target: np.ndarray | None = None) -> Features:
    """Features of every robot of an observation (batched or single world); `target` replaces the goal if given."""
    c, s = np.cos(obs.heading), np.sin(obs.heading)
    to_goal = (obs.goal if target is None else target) - obs.position
    dist = np.linalg.norm(to_goal, axis=-1, keepdims=True)
    to_goal = to_goal * np.minimum(1.0, goal_clip / np.maximum(dist, 1e-9))
    near = np.minimum(obs.obstacle_distance, sensing_radius)[..., None]
    own = np.concatenate([_rotate(to_goal, c, s), _rotate(obs.velocity, c, s),
                          _clip_obstacle(obs, c, s, sensing_radius), near], axis=-1)
    cc, ss = c[..., :, None], s[..., :, None]
    rel = _rotate(obs.rel_position, cc, ss)
    rel_v = _rotate(obs.rel_velocity, cc, ss)
    edge = np.concatenate([rel, rel_v, np.linalg.norm(rel, axis=-1, keepdims=True)], axis=-1)
    mask = obs.neighbours
    return Features(own.astype(np.float32), np.where(mask[..., None], edge, 0.0).astype(np.float32), mask)


def _clip_obstacle(obs: Observation, c: np.ndarray, s: np.ndarray, radius: float) -> np.ndarray:
    # Obstacles beyond the sensing radius are seen at the radius, in their direction.
    v = obs.obstacle
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return _rotate(v * np.minimum(1.0, radius / np.maximum(length, 1e-9)), c, s)
