"""Drives: how a commanded planar velocity becomes the robot's velocity, vectorized over (worlds, robots).

- holonomic: the velocity itself, bounded in speed and acceleration (STAF's Gazebo robots, Section 4).
- diff_drive: the same command turned into a linear speed along the heading and a bounded turn rate, as STAF does for
  its Warthog and Limo robots ("convert the linear velocity in the action a_i into wheel velocities", Section 4).
"""

from __future__ import annotations

import numpy as np

from stafpipe.scenario import RobotSpec


def limit_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """Scale the last-axis vectors of `v` down to norm at most `limit`."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


def holonomic(
    cmd: np.ndarray, vel: np.ndarray, heading: np.ndarray, robot: RobotSpec, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """New velocity (.., 2) and heading (..): speed capped at max_speed, change capped at max_accel * dt."""
    target = limit_norm(cmd, robot.max_speed)
    new = vel + limit_norm(target - vel, robot.max_accel * dt)
    moving = np.linalg.norm(new, axis=-1) > 1e-3
    return new, np.where(moving, np.arctan2(new[..., 1], new[..., 0]), heading)


def diff_drive(
    cmd: np.ndarray, vel: np.ndarray, heading: np.ndarray, robot: RobotSpec, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Unicycle tracking of the commanded velocity: turn towards it at most max_turn_rate, drive forward at the
    command's speed scaled by cos(heading error) (no reversing), acceleration bounded."""
    target = limit_norm(cmd, robot.max_speed)
    speed_cmd = np.linalg.norm(target, axis=-1)
    desired = np.where(speed_cmd > 1e-6, np.arctan2(target[..., 1], target[..., 0]), heading)
    err = (desired - heading + np.pi) % (2 * np.pi) - np.pi
    new_heading = heading + np.clip(err, -robot.max_turn_rate * dt, robot.max_turn_rate * dt)
    speed_now = np.linalg.norm(vel, axis=-1)
    speed_goal = speed_cmd * np.maximum(np.cos(err), 0.0)
    speed = speed_now + np.clip(speed_goal - speed_now, -robot.max_accel * dt, robot.max_accel * dt)
    return speed[..., None] * np.stack([np.cos(new_heading), np.sin(new_heading)], axis=-1), new_heading


DRIVES = {"holonomic": holonomic, "diff_drive": diff_drive}
