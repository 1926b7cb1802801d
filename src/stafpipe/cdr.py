"""ROS 2 CDR (little-endian, XCDR1) encoding of the episode log's five message types, straight from numpy arrays.

mcap-ros2-support's dynamic encoder walks every message as nested Python dicts, which cost about 1 ms per control step
for a team of ten (a third of an L&F evaluation's time, measured). These encoders write the same bytes
from the arrays: `tests/test_episode_log.py` checks them byte for byte against mcap-ros2-support's encoder, and the
logs are still read by its decoder (and by Foxglove and rosbag2, which read CDR).
"""

from __future__ import annotations

import math
import struct
from typing import NamedTuple

import numpy as np

_HEADER = b"\x00\x01\x00\x00"  # CDR little-endian encapsulation


class CdrBuffer:
    """Appends CDR fields, aligning each primitive to its size from the start of the payload (after the header)."""

    def __init__(self) -> None:
        self._parts: list[bytes] = []
        self._size = 0

    def _put(self, data: bytes, align: int) -> None:
        pad = -self._size % align
        if pad:
            self._parts.append(b"\x00" * pad)
        self._parts.append(data)
        self._size += pad + len(data)

    def int32(self, v: int) -> None:
        self._put(struct.pack("<i", v), 4)

    def uint32(self, v: int) -> None:
        self._put(struct.pack("<I", v), 4)

    def int64(self, v: int) -> None:
        self._put(struct.pack("<q", v), 8)

    def float64(self, v: float) -> None:
        self._put(struct.pack("<d", v), 8)

    def string(self, s: str) -> None:
        data = s.encode() + b"\x00"
        self.uint32(len(data))
        self._put(data, 1)

    def float64s(self, a: np.ndarray) -> None:
        """A sequence of float64, or (2-D) of structs of float64s, one row each."""
        a = np.ascontiguousarray(a, dtype="<f8")
        self.uint32(len(a))
        if a.size:
            self._put(a.tobytes(), 8)

    def int32s(self, a: np.ndarray) -> None:
        a = np.ascontiguousarray(a, dtype="<i4")
        self.uint32(len(a))
        if a.size:
            self._put(a.tobytes(), 4)

    def time(self, t: float) -> None:
        """builtin_interfaces/Time."""
        sec = math.floor(t)
        self.int32(int(sec))
        self.uint32(int(round((t - sec) * 1e9)))

    def bytes(self) -> bytes:
        return _HEADER + b"".join(self._parts)


def pose_array(t: float, pos: np.ndarray, heading: np.ndarray, frame_id: str = "map") -> bytes:
    """geometry_msgs/PoseArray: every robot's planar pose (z = 0, yaw as a quaternion about z)."""
    buf = CdrBuffer()
    buf.time(t)
    buf.string(frame_id)
    poses = np.zeros((len(pos), 7))
    poses[:, 0:2] = pos
    poses[:, 5] = np.sin(heading / 2)
    poses[:, 6] = np.cos(heading / 2)
    buf.float64s(poses)
    return buf.bytes()


def team_state(
    t: float,
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    targets: np.ndarray,
    subteams: np.ndarray,
    movers: np.ndarray,
) -> bytes:
    """stafpipe_msgs/TeamState."""
    buf = CdrBuffer()
    buf.time(t)
    buf.float64(t)
    for column in (pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1], heading, targets[:, 0], targets[:, 1]):
        buf.float64s(column)
    buf.int32s(subteams)
    buf.float64s(movers[:, 0])
    buf.float64s(movers[:, 1])
    return buf.bytes()


def episode_info(method: str, seed: int, scenario_yaml: str, context_json: str, goal: np.ndarray) -> bytes:
    """stafpipe_msgs/EpisodeInfo."""
    buf = CdrBuffer()
    buf.string(method)
    buf.int64(seed)
    buf.string(scenario_yaml)
    buf.string(context_json)
    buf.float64s(goal[:, 0])
    buf.float64s(goal[:, 1])
    return buf.bytes()


def event(t: float, step: int, kind: str, robots: list[int], detail: str) -> bytes:
    """stafpipe_msgs/Event."""
    buf = CdrBuffer()
    buf.float64(t)
    buf.int32(step)
    buf.string(kind)
    buf.int32s(np.asarray(robots, dtype=int))
    buf.string(detail)
    return buf.bytes()


def metrics(json_text: str) -> bytes:
    """stafpipe_msgs/EpisodeMetrics."""
    buf = CdrBuffer()
    buf.string(json_text)
    return buf.bytes()


class TeamStateArrays(NamedTuple):
    """A decoded stafpipe_msgs/TeamState, every sequence a numpy array."""

    time: float
    x: np.ndarray
    y: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    heading: np.ndarray
    target_x: np.ndarray
    target_y: np.ndarray
    subteam: np.ndarray
    mover_x: np.ndarray
    mover_y: np.ndarray


def read_team_state(data: bytes) -> TeamStateArrays:
    """Decode what `team_state` writes, each sequence in one numpy read: mcap-ros2-support's decoder builds a Python
    float per element (about 300 bytes a robot-step held, and most of `inspect`'s time on a long log)."""
    if data[:4] != _HEADER:
        raise ValueError("TeamState: not little-endian CDR")
    pos = 4

    def seq(dtype: str, size: int) -> np.ndarray:
        nonlocal pos
        pos += -(pos - 4) % 4
        (count,) = struct.unpack_from("<I", data, pos)
        pos += 4
        if count:
            pos += -(pos - 4) % size
        out = np.frombuffer(data, dtype=dtype, count=count, offset=pos).copy()
        pos += count * size
        return out

    pos += 8  # builtin_interfaces/Time: int32 sec, uint32 nanosec
    pos += -(pos - 4) % 8
    (time,) = struct.unpack_from("<d", data, pos)
    pos += 8
    x, y, vx, vy, heading, target_x, target_y = (seq("<f8", 8) for _ in range(7))
    subteam = seq("<i4", 4)
    mover_x, mover_y = seq("<f8", 8), seq("<f8", 8)
    return TeamStateArrays(time, x, y, vx, vy, heading, target_x, target_y, subteam, mover_x, mover_y)
