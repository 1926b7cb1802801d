"""EpisodeLog: one episode as an MCAP file with ROS 2 (CDR) message encodings, readable by Foxglove and as a rosbag2.

Channels: /episode (EpisodeInfo, once), /robots/poses (geometry_msgs/PoseArray), /robots/state (TeamState),
/events (Event), /metrics (EpisodeMetrics, once at the end). Message definitions are the .msg files beside this module.
Chunks carry CRCs and are small, so a killed run loses at most its last chunk; `recover` rewrites what is complete.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
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


def require_log_file(path: Path) -> None:
    """A clear LogError unless `path` is a file."""
    if not path.is_file():
        raise LogError(f"{path}: " + ("a directory, not an episode log" if path.is_dir() else "no such file"))


def _stream(path: Path, on_message: Callable[[str, Any], None]) -> str | None:
    """Decode every message of an episode log in log-time order, handing each to `on_message(topic, message)`, one
    chunk in memory at a time; the damage a recovered log was copied from, or None. A clear LogError where the file
    is missing, damaged or not a stafpipe episode log."""
    require_log_file(path)
    recovered = None
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            topics = sorted({c.topic for c in summary.channels.values()}) if summary is not None else None
            if topics is not None and "/episode" not in topics:
                raise LogError(
                    f"{path}: not a stafpipe episode log (its channels: {', '.join(topics) or 'none'}; an episode "
                    "log has /episode and /robots/state)"
                )
            for meta in reader.iter_metadata():
                if meta.name == RECOVERED:
                    recovered = meta.metadata.get("damage", "unknown")
            decoders: dict[int, Callable[[bytes], Any]] = {}
            factory = DecoderFactory()
            for schema, channel, msg in reader.iter_messages(log_time_order=True):
                if channel.topic == "/robots/state":
                    on_message(channel.topic, cdr.read_team_state(msg.data))
                elif channel.topic == "/robots/poses":  # the same poses as the states, for Foxglove
                    on_message(channel.topic, None)
                else:
                    if channel.id not in decoders:
                        decoder = factory.decoder_for(channel.message_encoding, schema)
                        if decoder is None:
                            raise LogError(
                                f"{path}: not a stafpipe episode log (no decoder for {channel.topic}, "
                                f"{channel.message_encoding})"
                            )
                        decoders[channel.id] = decoder
                    on_message(channel.topic, decoders[channel.id](msg.data))
    except (McapError, ValueError, KeyError, EOFError, OSError) as exc:
        raise LogError(
            f"{path}: not a readable MCAP episode log ({type(exc).__name__}: {exc}); try `stafpipe inspect --recover`"
        ) from None
    return recovered


def _event(msg: Any) -> dict[str, Any]:
    return {"time": msg.time, "step": msg.step, "kind": msg.kind, "robots": list(msg.robots), "detail": msg.detail}


def read_episode(path: str | Path) -> EpisodeRecord:
    """Read an episode log whole; a clear LogError if it is missing, damaged or not ours."""
    path = Path(path)
    info, states, events, metrics = None, [], [], None
    topics: dict[str, int] = {}

    def take(topic: str, msg: Any) -> None:
        nonlocal info, metrics
        topics[topic] = topics.get(topic, 0) + 1
        if topic == "/episode":
            info = msg
        elif topic == "/robots/state":
            states.append(msg)
        elif topic == "/events":
            events.append(_event(msg))
        elif topic == "/metrics":
            metrics = json.loads(msg.json)

    recovered = _stream(path, take)
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


@dataclass
class EpisodeOutline:
    """What `stafpipe inspect` shows of a log without holding its states: read message by message, in memory that
    does not grow with the episode's length."""

    method: str = ""
    seed: int = 0
    robots: int = 0
    steps: int = 0
    duration: float = 0.0
    topics: dict[str, int] = field(default_factory=dict)
    changes: list[tuple[float, np.ndarray]] = field(default_factory=list)
    """(time, subteam labels) where the subteams change (the first `MAX_CHANGES` of them)."""
    events: dict[str, int] = field(default_factory=dict)
    recovered: str | None = None


MAX_CHANGES = 20


def outline_episode(path: str | Path) -> EpisodeOutline:
    """The outline of an episode log of any size; a clear LogError if it is missing, damaged or not ours."""
    path, out = Path(path), EpisodeOutline()
    last: np.ndarray | None = None

    def take(topic: str, msg: Any) -> None:
        nonlocal last
        out.topics[topic] = out.topics.get(topic, 0) + 1
        if topic == "/episode":
            out.method, out.seed = msg.method, int(msg.seed)
        elif topic == "/robots/state":
            labels = np.asarray(msg.subteam, int)
            out.robots, out.steps, out.duration = len(labels), out.steps + 1, float(msg.time)
            if (last is None or not np.array_equal(labels, last)) and len(out.changes) < MAX_CHANGES:
                out.changes.append((float(msg.time), labels))
            last = labels
        elif topic == "/events":
            out.events[msg.kind] = out.events.get(msg.kind, 0) + 1

    out.recovered = _stream(path, take)
    if not out.method or not out.steps:
        raise LogError(f"{path}: not a stafpipe episode log (no /episode or /robots/state messages)")
    return out


def recover(src: str | Path, dst: str | Path) -> tuple[int, int, list[Damage]]:
    """Copy every intact chunk's records of a truncated or damaged MCAP episode log into a valid one, also those after
    a damaged chunk (mcap_check.intact_records). The copy carries a `stafpipe.recovered` metadata record naming the
    damage, so that it reads as a partial episode. Returns (messages kept, channels, the damage found); an intact log
    is not copied (0, 0, []), and an MCAP file of another tool is refused."""
    src = Path(src)
    require_log_file(src)
    data = src.read_bytes()
    scan = intact_records(data)
    damage = check(data, scan)
    topics = sorted({c.topic for c in scan.channels.values()})
    if topics and "/episode" not in topics:
        raise LogError(f"{src}: not a stafpipe episode log (its channels: {', '.join(topics)}); nothing recovered")
    if not damage:
        return 0, 0, []
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
