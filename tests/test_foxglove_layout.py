"""The shipped Foxglove layout opens what an episode log holds: every topic and field path it names exists in an
MCAP file that `stafpipe eval` writes (so a renamed channel or field cannot leave the layout silently blank)."""

from __future__ import annotations

import json
import re

import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from conftest import job_dirs
from stafpipe.episode_log import TOPICS
from stafpipe.launch import launch
from stafpipe.paths import package_dir

LAYOUT = package_dir() / "foxglove" / "episode_layout.json"


def layout_paths(layout: dict) -> list[str]:
    """Every message path a panel of the layout reads (topicPath, paths[].value, topics)."""
    out = []
    for config in layout["configById"].values():
        if "topicPath" in config:
            out.append(config["topicPath"])
        out += [p["value"] for p in config.get("paths", [])]
        out += list(config.get("topics", {}))
    return out


@pytest.mark.slow  # one STAF episode, about 5 s
def test_every_path_of_the_layout_reads_a_field_of_an_episode_log(workdir) -> None:
    layout = json.loads(LAYOUT.read_text())
    panels = set(re.findall(r'"([A-Za-z0-9]+![A-Za-z0-9]+)"', json.dumps(layout["layout"])))
    assert panels == set(layout["configById"])  # every panel placed, every placed panel configured
    assert launch("eval", ["method=staf_planned", "eval.episodes=1", "scenario.time_limit=2"]) == 0
    [run] = job_dirs(workdir)
    first: dict[str, object] = {}
    with open(run / "episodes" / "episode_0000.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        # a channel appears with its first message (an episode without events has no /events): TOPICS lists all
        channels = {c.topic for c in reader.get_summary().channels.values()} | set(TOPICS)
        for _, channel, _, msg in reader.iter_decoded_messages():
            first.setdefault(channel.topic, msg)
    paths = layout_paths(layout)
    assert {"/robots/poses", "/events", "/metrics.json", "/episode"} <= set(paths) and len(paths) > 20
    for path in paths:
        topic = max((t for t in channels if path == t or path.startswith(t + ".")), key=len, default=None)
        assert topic is not None, f"{path}: no such topic in an episode log ({sorted(channels)})"
        if path == topic:
            continue
        value = first[topic]  # a field path: read it off the topic's first message
        for name, index in re.findall(r"\.(\w+)(?:\[(\d+)\])?", path[len(topic) :]):
            assert hasattr(value, name), f"{path}: {type(value).__name__} has no field {name}"
            value = getattr(value, name)
            if index:
                assert int(index) < len(value), f"{path}: index beyond the logged team of {len(value)}"
                value = value[int(index)]
