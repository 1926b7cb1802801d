"""The episode log's CDR encoders write exactly the bytes of mcap-ros2-support's own encoder."""

import io
import json

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.writer import Writer

from stafpipe import cdr
from stafpipe.episode_log import TOPICS, _msgdef


def _library_bytes(topic: str, message: dict) -> bytes:
    out = io.BytesIO()
    writer = Writer(out)
    writer.write_message(topic, writer.register_msgdef(TOPICS[topic], _msgdef(TOPICS[topic])), message, log_time=0)
    writer.finish()
    [(_, _, msg)] = list(make_reader(io.BytesIO(out.getvalue())).iter_messages())
    return msg.data


@pytest.mark.parametrize("n", [0, 1, 7])
def test_every_message_matches_the_library_encoder_byte_for_byte(n) -> None:
    rng = np.random.default_rng(n)
    t = float(rng.uniform(0, 100))
    pos, vel, targets = rng.normal(size=(3, n, 2))
    heading = rng.uniform(-np.pi, np.pi, n)
    subteams = rng.integers(0, 4, n)
    movers = rng.normal(size=(n // 2, 2))
    stamp = {"sec": int(np.floor(t)), "nanosec": int(round((t - np.floor(t)) * 1e9))}
    poses = [
        {
            "position": {"x": p[0], "y": p[1], "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": np.sin(h / 2), "w": np.cos(h / 2)},
        }
        for p, h in zip(pos, heading, strict=True)
    ]
    assert cdr.pose_array(t, pos, heading) == _library_bytes(
        "/robots/poses", {"header": {"stamp": stamp, "frame_id": "map"}, "poses": poses}
    )
    state = {
        "stamp": stamp,
        "time": t,
        "x": pos[:, 0].tolist(),
        "y": pos[:, 1].tolist(),
        "vx": vel[:, 0].tolist(),
        "vy": vel[:, 1].tolist(),
        "heading": heading.tolist(),
        "target_x": targets[:, 0].tolist(),
        "target_y": targets[:, 1].tolist(),
        "subteam": subteams.tolist(),
        "mover_x": movers[:, 0].tolist(),
        "mover_y": movers[:, 1].tolist(),
    }
    assert cdr.team_state(t, pos, vel, heading, targets, subteams, movers) == _library_bytes("/robots/state", state)
    context = json.dumps({"eta": 2.17, "name": "é"})
    info = {
        "method": "staf_planned",
        "seed": -3 + n,
        "scenario_yaml": "a: 1\n" * n,
        "context_json": context,
        "goal_x": pos[:, 0].tolist(),
        "goal_y": pos[:, 1].tolist(),
    }
    assert cdr.episode_info("staf_planned", -3 + n, "a: 1\n" * n, context, pos) == _library_bytes("/episode", info)
    robots = list(range(n))
    event = {"time": t, "step": 5 * n, "kind": "split", "robots": robots, "detail": "x" * n}
    assert cdr.event(t, 5 * n, "split", robots, "x" * n) == _library_bytes("/events", event)
    assert cdr.metrics(context) == _library_bytes("/metrics", {"json": context})


@pytest.mark.parametrize("n", [0, 1, 7])
def test_the_team_state_reader_gives_what_the_library_decoder_gives(n) -> None:
    """`read_team_state` (numpy reads, used by inspect) decodes every field as mcap-ros2-support's decoder does, odd
    counts (the int32 subteams then misalign the next float64 sequence) and moving obstacles included."""
    from mcap_ros2.decoder import DecoderFactory

    rng = np.random.default_rng(10 + n)
    pos, vel, targets = rng.normal(size=(3, n, 2))
    data = cdr.team_state(
        12.375, pos, vel, rng.normal(size=n), targets, rng.integers(0, 4, n), rng.normal(size=(n // 2 + 1, 2))
    )
    out = io.BytesIO()
    writer = Writer(out)
    writer.write_message(
        "/robots/state",
        writer.register_msgdef(TOPICS["/robots/state"], _msgdef(TOPICS["/robots/state"])),
        {},
        log_time=0,
    )
    writer.finish()
    [(schema, channel, _)] = list(make_reader(io.BytesIO(out.getvalue())).iter_messages())
    expected = DecoderFactory().decoder_for(channel.message_encoding, schema)(data)
    got = cdr.read_team_state(data)
    assert got.time == expected.time == 12.375
    for field in got._fields[1:]:
        assert np.array_equal(getattr(got, field), np.asarray(getattr(expected, field))), field
