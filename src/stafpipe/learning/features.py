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

from stafpipe.geometry import lengths, point_ahead
from stafpipe.sensing import Observation

OWN, EDGE = 7, 5


class Features(NamedTuple):
    own: np.ndarray
    """(.., n, 7)"""
    edge: np.ndarray
    """(.., n, n, 5) [i, j]: what i knows of neighbour j."""
    mask: np.ndarray
    """(.., n, n) bool: j is i's neighbour."""


def to_robot_frame(v: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Express world-frame vectors v (.., 2) in frames of heading (cos c, sin s): R(-heading) v."""
    return stack_xy(c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1])


def stack_xy(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(.., 2) from two (..) arrays: np.stack(axis=-1)'s result without its call overhead (every control step)."""
    out = np.empty(x.shape + (2,), dtype=np.result_type(x, y))
    out[..., 0], out[..., 1] = x, y
    return out


def to_robot_frames(vs: list[np.ndarray], c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(.., 2 len(vs)) `to_robot_frame` of each of the vectors `vs` (each .., 2), side by side: one rotation for all
    (the same products and sums element by element, so the same bits)."""
    v = np.stack(vs, axis=-2)
    return to_robot_frame(v, c[..., None], s[..., None]).reshape(v.shape[:-2] + (2 * len(vs),))


def guide_targets(
    pos: np.ndarray,
    goal: np.ndarray,
    path: np.ndarray,
    lookahead: float,
    release: float,
    near: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(n, 2) targets of one world's robots: the point `lookahead` ahead of each robot's projection on `path` (K, 2),
    or the robot's own goal once its projection is within `release` of the path's end; and (n,) the arc length left
    after each projection. `near` (n,): arc lengths near which to project (`point_ahead`: a route that comes back
    near itself)."""
    point, _, left = point_ahead(path, pos, lookahead, near=near)
    return np.where((left < release)[:, None], goal, point), left


def features(obs: Observation, goal_clip: float, sensing_radius: float, target: np.ndarray | None = None) -> Features:
    """Features of every robot of an observation (batched or single world); `target` replaces the goal if given."""
    c, s = np.cos(obs.heading), np.sin(obs.heading)
    to_goal = (obs.goal if target is None else target) - obs.position
    dist = np.linalg.norm(to_goal, axis=-1, keepdims=True)
    to_goal = to_goal * np.minimum(1.0, goal_clip / np.maximum(dist, 1e-9))
    near = np.minimum(obs.obstacle_distance, sensing_radius)[..., None]
    own = np.concatenate(
        [
            to_robot_frame(to_goal, c, s),
            to_robot_frame(obs.velocity, c, s),
            _clip_obstacle(obs, c, s, sensing_radius),
            near,
        ],
        axis=-1,
    )
    cc, ss = c[..., :, None], s[..., :, None]
    rel = to_robot_frame(obs.rel_position, cc, ss)
    rel_v = to_robot_frame(obs.rel_velocity, cc, ss)
    edge = np.concatenate([rel, rel_v, np.linalg.norm(rel, axis=-1, keepdims=True)], axis=-1)
    mask = obs.heard  # the communication graph: what neighbours sent (faults applied)
    return Features(own.astype(np.float32), np.where(mask[..., None], edge, 0.0).astype(np.float32), mask)


def _clip_obstacle(obs: Observation, c: np.ndarray, s: np.ndarray, radius: float) -> np.ndarray:
    # Obstacles beyond the sensing radius are seen at the radius, in their direction.
    v = obs.obstacle
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return to_robot_frame(v * np.minimum(1.0, radius / np.maximum(length, 1e-9)), c, s)


STAF_OWN, STAF_EDGE = 6, 9


def staf_features(
    obs: Observation,
    target: np.ndarray,
    same: np.ndarray,
    goal_clip: float,
    sensing_radius: float,
    drive_flag: np.ndarray | None = None,
) -> Features:
    """STAF's robot states s (Sec. 3, Problem Definition: position, goal, velocity, closest obstacle), in robot i's
    frame. Own (.., n, 6): s_i = [t_i - p_i (clipped), q_i, c_i] (its position is the frame's origin); edge
    (.., n, n, 9): s_j - s_i = [p_j - p_i, t_j - t_i, q_j - q_i, c_j - c_i, same_ij - 1], where t is the robot's target
    from the plan (its subteam slot, later its goal) and same_ij says whether j is in i's subteam. z_j - z_i of the
    intermediate GNN is W^z applied to this difference (staf_net.py). `drive_flag` (B,) (`policy.drive_input`): a 7th
    own entry per robot, 1 where its world's robots have a differential drive."""
    c, s = np.cos(obs.heading), np.sin(obs.heading)
    to_target = target - obs.position
    dist = lengths(to_target, keepdims=True)
    clipped = to_target * np.minimum(1.0, goal_clip / np.maximum(dist, 1e-9))
    length = lengths(obs.obstacle, keepdims=True)
    obstacle = obs.obstacle * np.minimum(1.0, sensing_radius / np.maximum(length, 1e-9))  # seen at most at the radius
    own = to_robot_frames([clipped, obs.velocity, obstacle], c, s)
    if drive_flag is not None:
        flag = np.broadcast_to(np.asarray(drive_flag, float)[..., None, None], own.shape[:-1] + (1,))  # per world
        own = np.concatenate([own, flag], axis=-1)
    cc, ss = c[..., :, None], s[..., :, None]
    pair = lambda v: v[..., None, :, :] - v[..., :, None, :]  # noqa: E731  [i, j] = v_j - v_i
    rotated = to_robot_frames([obs.rel_position, pair(target), obs.rel_velocity, pair(obstacle)], cc, ss)
    diff = np.concatenate([rotated, (same.astype(np.float32) - 1.0)[..., None]], axis=-1)
    mask = obs.heard  # the communication graph: what neighbours sent (faults applied)
    return Features(own.astype(np.float32), np.where(mask[..., None], diff, 0.0).astype(np.float32), mask)


def staf_pairs(
    position: np.ndarray,
    velocity: np.ndarray,
    heading: np.ndarray,
    obstacle: np.ndarray,
    target: np.ndarray,
    labels: np.ndarray,
    goal_clip: float,
    sensing_radius: float,
    radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`staf_features` of one world as an edge list (large teams): own (n, 6), receiver (E,), diff (E, 9) for every
    ordered pair within `radius` (a k-d tree finds them; perfect sensing)."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(position).query_pairs(radius, output_type="ndarray")
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    c, s = np.cos(heading), np.sin(heading)
    to_target = target - position
    dist = np.linalg.norm(to_target, axis=-1, keepdims=True)
    clipped = to_target * np.minimum(1.0, goal_clip / np.maximum(dist, 1e-9))
    length = np.linalg.norm(obstacle, axis=-1, keepdims=True)
    obstacle = obstacle * np.minimum(1.0, sensing_radius / np.maximum(length, 1e-9))
    own = np.concatenate(
        [to_robot_frame(clipped, c, s), to_robot_frame(velocity, c, s), to_robot_frame(obstacle, c, s)], axis=-1
    )
    ci, si = c[i], s[i]
    diff = np.concatenate(
        [
            to_robot_frame(position[j] - position[i], ci, si),
            to_robot_frame(target[j] - target[i], ci, si),
            to_robot_frame(velocity[j] - velocity[i], ci, si),
            to_robot_frame(obstacle[j] - obstacle[i], ci, si),
            (labels[j] == labels[i]).astype(float)[:, None] - 1.0,
        ],
        axis=-1,
    )
    return own.astype(np.float32), i, diff.astype(np.float32)


def flat_rows(own: np.ndarray, edge: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(n, F + n (E + 1)) one team's features as one row per robot, the PettingZoo form's observation
    (`stafpipe.marl_env`): its own features, then for every robot j its edge features and whether it is heard."""
    return np.concatenate([own, np.concatenate([edge, mask[..., None]], -1).reshape(len(own), -1)], -1)
