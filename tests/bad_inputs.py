"""Every kind of bad input we refuse (the table is tests/data/bad_inputs.yaml): `tests/test_bad_inputs.py` runs each
case; `python tests/bad_inputs.py` prints the table of docs/bad_inputs.md with the messages as they are now.

Each case runs in an empty working directory ({tmp} in its words); its `files` are written there first: text,
`{bytes: HEX}`, or `@name` for a file made here (a truncated checkpoint, an episode log with a flipped byte).
"""

from __future__ import annotations

import dataclasses
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

HERE = Path(__file__).resolve().parent
CHECKPOINTS = HERE.parent / "src" / "stafpipe" / "checkpoints"
FILE_FAULTS = ("read-only run directory", "disk full while writing", "read-only working directory")
"""Cases whose fault test_bad_inputs.py makes by patching the file system (a mount needs privileges CI may not have)."""


@dataclass
class Case:
    kind: str
    group: str
    words: list[str]
    """The command line after `stafpipe`."""
    said: str
    """A part of the message that names what is wrong."""
    files: dict[str, Any] = field(default_factory=dict)
    tested_in: str = "tests/test_bad_inputs.py"
    """The test that covers it (a case another test already runs is not run twice)."""


def load_cases() -> list[Case]:
    return [Case(**c) for c in yaml.safe_load((HERE / "data" / "bad_inputs.yaml").read_text())]


def episode_log(tmp: Path) -> bytes:
    """A short, intact episode log (made once and kept in tests/.cache)."""
    cached = HERE / ".cache" / "episode.mcap"
    if not cached.is_file():
        from typer.testing import CliRunner

        from stafpipe.cli import app

        out = tmp / "_log"
        words = ["eval", "method=straight", "scenario=corridor", "eval.episodes=1", "scenario.time_limit=3"]
        assert CliRunner().invoke(app, [*words, f"hydra.run.dir={out}"]).exit_code == 0
        cached.parent.mkdir(exist_ok=True)
        shutil.copy(out / "episodes" / "episode_0000.mcap", cached)
        shutil.rmtree(out)
    return cached.read_bytes()


def _policy(tmp: Path, method: str, hidden: int, recorded_hidden: int | None = None) -> bytes:
    """A policy checkpoint of `hidden` units; `recorded_hidden` other than it: weights that do not fit the network
    the checkpoint's own config describes."""
    from stafpipe.learning.checkpoint import FORMAT, build_policy
    from stafpipe.learning.config import PolicyConfig
    from stafpipe.torch_io import save_payload

    policy = build_policy(method, PolicyConfig(hidden=hidden))
    recorded = dataclasses.asdict(PolicyConfig(hidden=recorded_hidden or hidden))
    payload = {"format": FORMAT, "method": method, "policy": recorded, "state_dict": policy.state_dict()}
    return save_payload(tmp / "_made.pt", {**payload, "made_by": {}}).read_bytes()


def _flipped(tmp: Path) -> bytes:
    data = bytearray(episode_log(tmp))
    data[len(data) // 2] ^= 0x01
    return bytes(data)


def _foreign_mcap(tmp: Path) -> bytes:
    """A valid MCAP file of another tool: JSON messages on /foo."""
    import io

    from mcap.writer import Writer

    out = io.BytesIO()
    writer = Writer(out)
    writer.start()
    schema = writer.register_schema(name="Foo", encoding="jsonschema", data=b"{}")
    channel = writer.register_channel(topic="/foo", message_encoding="json", schema_id=schema)
    for k in range(3):
        writer.add_message(channel_id=channel, log_time=k, data=b"{}", publish_time=k)
    writer.finish()
    return out.getvalue()


MAKERS = {
    "@foreign_mcap": _foreign_mcap,
    "@policy_other_shape": lambda tmp: _policy(tmp, "staf_planned", 16, recorded_hidden=64),
    "@policy_small": lambda tmp: _policy(tmp, "dgnn", 8),
    "@policy_small_staf": lambda tmp: _policy(tmp, "staf_planned", 8),
    "@episode_log_flipped": _flipped,
    "@episode_log_truncated": lambda tmp: episode_log(tmp)[:3000],
    "@truncated staf_planned.pt": lambda tmp: (CHECKPOINTS / "staf_planned.pt").read_bytes()[:5000],
    "@truncated high_level.pt": lambda tmp: (CHECKPOINTS / "high_level.pt").read_bytes()[:5000],
}


def write_files(case: Case, tmp: Path) -> None:
    for name, content in case.files.items():
        if isinstance(content, dict):
            data = bytes.fromhex(content["bytes"])
        elif content in MAKERS:
            data = MAKERS[content](tmp)
        else:
            data = content.encode()
        path = tmp / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


def words_of(case: Case, tmp: Path) -> list[str]:
    return [w.replace("{tmp}", str(tmp)).replace("{checkpoints}", str(CHECKPOINTS)) for w in case.words]


def run_case(case: Case, tmp: Path) -> tuple[int, str]:
    """Write the case's files into `tmp` (its working directory) and run it in-process: (exit code, output)."""
    from typer.testing import CliRunner

    from stafpipe.cli import app

    write_files(case, tmp)
    result = CliRunner().invoke(app, words_of(case, tmp))
    return result.exit_code, result.output


def markdown() -> str:
    """The table of docs/bad_inputs.md, every case run now (file-system faults as test_bad_inputs.py makes them)."""
    import os
    import tempfile

    lines = ["| # | group | bad input | `stafpipe ...` | exit | message | test |", "|---|---|---|---|---|---|---|"]
    here = Path.cwd()
    for k, case in enumerate(load_cases(), 1):
        with tempfile.TemporaryDirectory() as d:
            os.chdir(d)
            try:
                if case.kind in FILE_FAULTS:
                    from test_bad_inputs import run_file_fault

                    code, out = run_file_fault(case, Path(d))
                else:
                    code, out = run_case(case, Path(d))
            finally:
                os.chdir(here)
            out = out.replace(str(Path(d).resolve()) + "/", "").replace(d + "/", "").replace(d, ".")
        message = " ".join(line for line in out.splitlines() if line.startswith("error:"))
        message = (message or out.strip().splitlines()[-1]).replace("|", "\\|")
        message = message.replace("] [", "] \\[")  # not a Markdown reference link `[a] [b]`
        words = " ".join(case.words).replace("{tmp}/", "").replace("{tmp}", ".").replace("{checkpoints}/", "")
        test = case.tested_in.replace("tests/", "")
        lines.append(f"| {k} | {case.group} | {case.kind} | `{words}` | {code} | {message} | {test} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown())
