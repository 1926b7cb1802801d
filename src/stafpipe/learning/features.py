"""What a learned policy sees, per robot in its own frame (rotated by its heading), from the harness' Observation.

Own features (7): goal vector (clipped), own velocity, vector to the closest obstacle point (STAF's c_i) and its
distance. Edge features (5) for each neighbour j within the communication radius: its relative position, relative
velocity and distance. No global path planner: the goal vector is the straight line to the robot's own goal.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

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


def features(obs: Observation, goal_clip: float, sensing_radius: float) -> Features:
    """Features of every robot of an observation (batched or single world)."""
    c, s = np.cos(obs.heading), np.sin(obs.heading)
    to_goal = obs.goal - obs.position
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
