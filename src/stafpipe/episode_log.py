"""EpisodeLog: one episode as an MCAP file with ROS 2 (CDR) message encodings, readable by Foxglove and as a rosbag2.

Channels: /episode (EpisodeInfo, once), /robots/poses (geometry_msgs/PoseArray), /robots/state (TeamState),
/events (Event), /metrics (EpisodeMetrics, once at the end). Message definitions are the .msg files beside this module.
Chunks carry CRCs and are small, so a killed run loses at most its last chunk; `recover` rewrites what is complete.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import Writer as RawWriter
from mcap_ros2.decoder import DecoderFactory

from stafpipe import cdr
from stafpipe.errors import StafpipeError
from stafpipe.mcap_check import Damage, check, intact_records, seal_data_crc

_MSG_DIR = Path(__file__).with_name("msg")
CHUNK_SIZE = 32 * 1024
RECOVERED = "stafpipe.recovered"
"""Metadata record of a file written by `recover`: a partial episode."""
TOPICS = {
    "/episode": "stafpipe_msgs/msg/EpisodeInfo",
    "/robots/poses": "geometry_msgs/msg/PoseArray",
    "/robots/state": "stafpipe_msgs/msg/TeamState",
    "/events": "stafpipe_msgs/msg/Event",
    "/metrics": "stafpipe_msgs/msg/EpisodeMetrics",
}


class LogError(StafpipeError):
    """An MCAP file is missing, truncated or not an episode log."""


def _msgdef(datatype: str) -> str:
    return (_MSG_DIR / (datatype.replace("/msg/", "__") + ".msg")).read_text()


class EpisodeLogWriter:
    """Writes one episode; the file appears under its final name only when `close` completes."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.partial = self.path.with_name(self.path.name + ".part")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: BinaryIO = open(self.partial, "w+b")  # noqa: SIM115 - closed in close()
        self._writer = RawWriter(self._file, chunk_size=CHUNK_SIZE, enable_crcs=True)
        self._writer.start(profile="ros2", library="stafpipe")
        self._channels = {
            topic: self._writer.register_channel(
                topic=topic,
                message_encoding="cdr",
                schema_id=self._writer.register_schema(name=dt, encoding="ros2msg", data=_msgdef(dt).encode()),
            )
            for topic, dt in TOPICS.items()
        }

    def _write(self, topic: str, data: bytes, t: float) -> None:
        """One CDR-encoded message (`cdr`) on `topic` at time t."""
        stamp = int(t * 1e9)
        self._writer.add_message(channel_id=self._channels[topic], log_time=stamp, data=data, publish_time=stamp)

    def info(self, method: str, seed: int, scenario_yaml: str, context: dict[str, Any], goal: np.ndarray) -> None:
        """The episode's header: scenario, metric context, team goal."""
        self._write("/episode", cdr.episode_info(method, seed, scenario_yaml, json.dumps(context), goal), 0.0)

    def state(
        self,
        t: float,
        pos: np.ndarray,
        vel: np.ndarray,
        heading: np.ndarray,
        targets: np.ndarray,
        subteams: np.ndarray,
        movers: np.ndarray,
    ) -> None:
        """One control step."""
        self._write("/robots/poses", cdr.pose_array(t, pos, heading), t)
        self._write("/robots/state", cdr.team_state(t, pos, vel, heading, targets, subteams, movers), t)

    def event(self, t: float, step: int, kind: str, robots: list[int], detail: str = "") -> None:
        """A split, merge, fault or collision."""
        self._write("/events", cdr.event(t, step, kind, robots, detail), t)

    def metrics(self, t: float, values: dict[str, float]) -> None:
        """The live metrics, at the end."""
        self._write("/metrics", cdr.metrics(json.dumps(values)), t)

    def close(self) -> Path:
        """Finish the file (summary, footer) and move it to its final name."""
        self._writer.finish()
        self._file.flush()
        seal_data_crc(self._file)
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()
        os.replace(self.partial, self.path)
        return self.path


@dataclass
class EpisodeRecord:
    """An episode read back from MCAP."""

    method: str
    seed: int
    scenario_yaml: str
    context: dict[str, Any]
    goal: np.ndarray
    time: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    headings: np.ndarray
    targets: np.ndarray
    subteams: np.ndarray
    movers: np.ndarray
    events: list[dict[str, Any]] = field(default_factory=list)
    metrics: dict[str, float] | None = None
    topics: dict[str, int] = field(default_factory=dict)
    recovered: str | None = None
    """The damage a recovered (partial) log was copied from; None for a log as written."""


def read_episode(path: str | Path) -> EpisodeRecord:
    """Read an episode log; a clear LogError if it is missing, damaged or not ours."""
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: " + ("a directory, not an episode log" if Path(path).is_dir() else "no such file"))
    info, states, events, metrics, recovered = None, [], [], None, None
    topics: dict[str, int] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
            for meta in reader.iter_metadata():
                if meta.name == RECOVERED:
                    recovered = meta.metadata.get("damage", "unknown")
            for _, channel, _, msg in reader.iter_decoded_messages(log_time_order=True):
                topic = channel.topic
                topics[topic] = topics.get(topic, 0) + 1
                if topic == "/episode":
                    info = msg
                elif topic == "/robots/state":
                    states.append(msg)
                elif topic == "/events":
                    events.append(
                        {
                            "time": msg.time,
                            "step": msg.step,
                            "kind": msg.kind,
                            "robots": list(msg.robots),
                            "detail": msg.detail,
                        }
                    )
                elif topic == "/metrics":
                    metrics = json.loads(msg.json)
    except (McapError, ValueError, KeyError, EOFError, OSError) as exc:
        raise LogError(
            f"{path}: not a readable MCAP episode log ({type(exc).__name__}: {exc}); try `stafpipe inspect --recover`"
        ) from None
    if info is None or not states:
        raise LogError(f"{path}: not a stafpipe episode log (no /episode or /robots/state messages)")
    arr = lambda *keys: np.stack([np.stack([np.asarray(getattr(s, k), float) for k in keys], -1) for s in states])  # noqa: E731
    return EpisodeRecord(
        method=info.method,
        seed=int(info.seed),
        scenario_yaml=info.scenario_yaml,
        context=json.loads(info.context_json),
        goal=np.stack([info.goal_x, info.goal_y], -1),
        time=np.array([s.time for s in states]),
        positions=arr("x", "y"),
        velocities=arr("vx", "vy"),
        headings=np.stack([np.asarray(s.heading, float) for s in states]),
        targets=arr("target_x", "target_y"),
        subteams=np.stack([np.asarray(s.subteam, int) for s in states]),
        movers=arr("mover_x", "mover_y"),
        events=events,
        metrics=metrics,
        topics=topics,
        recovered=recovered,
    )


def recover(src: str | Path, dst: str | Path) -> tuple[int, int, list[Damage]]:
    """Copy every intact chunk's records of a truncated or damaged MCAP file into a valid one, also those after a
    damaged chunk (mcap_check.intact_records). The copy carries a `stafpipe.recovered` metadata record naming the
    damage, so that it reads as a partial episode. Returns (messages kept, channels, the damage found)."""
    src = Path(src)
    if not src.is_file():
        raise LogError(f"{src}: " + ("a directory, not an episode log" if Path(src).is_dir() else "no such file"))
    data = src.read_bytes()
    scan = intact_records(data)
    damage = check(data, scan)
    messages = [m for m in scan.messages if m.channel_id in scan.channels]
    if not messages:
        raise LogError(f"{src}: no complete message could be recovered")
    dst = Path(dst)
    tmp = dst.with_name(dst.name + ".part")
    try:
        with open(tmp, "wb") as out:
            writer = RawWriter(out, chunk_size=CHUNK_SIZE, enable_crcs=True, enable_data_crcs=True)
            writer.start(profile="ros2", library="stafpipe recover")
            schema_ids = {
                old: writer.register_schema(name=s.name, encoding=s.encoding, data=s.data)
                for old, s in scan.schemas.items()
            }
            channel_ids = {
                old: writer.register_channel(
                    topic=c.topic,
                    message_encoding=c.message_encoding,
                    schema_id=schema_ids.get(c.schema_id, 0),
                    metadata=c.metadata,
                )
                for old, c in scan.channels.items()
            }
            for m in messages:
                writer.add_message(
                    channel_id=channel_ids[m.channel_id],
                    log_time=m.log_time,
                    data=m.data,
                    publish_time=m.publish_time,
                    sequence=m.sequence,
                )
            writer.add_metadata(RECOVERED, {"source": src.name, "damage": "; ".join(map(str, damage)) or "none"})
            writer.finish()
        os.replace(tmp, dst)
    finally:
        tmp.unlink(missing_ok=True)
    return len(messages), len(scan.channels), damage
