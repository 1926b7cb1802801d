"""Peak memory of `stafpipe inspect` on episode logs of growing size: one a real episode wrote, one stretched to the
largest that inspect recomputes the metrics of (`inspect_log.MAX_RECOMPUTED` robot-steps), and one of about 2 GB
that it checks and outlines message by message.

Usage: python benchmarks/inspect_memory.py [--gigabytes 2.0] [--keep DIR]
Target (issue 64): inspect on a 2 GB log stays under 500 MB of memory. Each inspect runs in a fresh process; its peak
resident set (its VmHWM) is printed with its wall time and exit code. The stretched logs repeat a real
episode's first state with a small drift, so their metrics mean nothing; only their size and shape matter here.
Writing the 2 GB log takes a few minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from stafpipe.episode_log import EpisodeLogWriter, read_episode
from stafpipe.inspect_log import MAX_RECOMPUTED
from stafpipe.launch import launch


def real_log(tmp: Path) -> Path:
    """A 10-robot corridor episode of `method=straight`, 5 s."""
    words = ["method=straight", "scenario=corridor", "eval.episodes=1", "scenario.time_limit=5"]
    if launch("eval", [*words, f"hydra.run.dir={tmp / 'real'}"]) != 0:
        raise SystemExit("the eval that writes the real log failed")
    return tmp / "real" / "episodes" / "episode_0000.mcap"


def stretched(source: Path, out: Path, robots: int, steps: int) -> Path:
    """A log of `steps` states of `robots` robots with the header of `source`."""
    rec = read_episode(source)
    rng = np.random.default_rng(0)
    reps = -(-robots // rec.positions.shape[1])
    pos = np.tile(rec.positions[0], (reps, 1))[:robots]
    vel = np.zeros_like(pos)
    heading, labels = np.zeros(robots), np.zeros(robots, dtype=int)
    writer = EpisodeLogWriter(out)
    writer.info(rec.method, rec.seed, rec.scenario_yaml, rec.context, np.tile(rec.goal, (reps, 1))[:robots])
    for k in range(steps):
        pos = pos + rng.normal(0.0, 0.01, pos.shape)
        writer.state(k * 0.1, pos, vel, heading, pos, labels, rec.movers[0])
    writer.metrics(steps * 0.1, {})
    return writer.close()


CHILD = """
import sys
from stafpipe.cli import app
code = 0
try:
    app(["inspect", sys.argv[1]])
except SystemExit as exc:
    code = exc.code or 0
peak = next(line for line in open("/proc/self/status") if line.startswith("VmHWM")).split()[1]
print("PEAK", peak, code, file=sys.stderr)
"""


def inspect_peak(path: Path) -> tuple[float, float, int]:
    """Peak resident MB, seconds and exit code of `stafpipe inspect PATH` in a fresh process: its own high-water mark
    (VmHWM, Linux), read at its end; a parent's getrusage of children would count the pages of the forked parent."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    line = next((x for x in done.stderr.splitlines() if x.startswith("PEAK ")), None)
    if line is None:
        raise SystemExit(f"inspect {path} did not finish: {done.stderr[-2000:]}")
    _, kb, code = line.split()
    return int(kb) / 1024, seconds, int(code)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--gigabytes", type=float, default=2.0, help="size of the largest log")
    parser.add_argument("--keep", default="", help="write the logs here and keep them (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        tmp = Path(args.keep or scratch)
        tmp.mkdir(parents=True, exist_ok=True)
        real = real_log(tmp)
        probe = stretched(real, tmp / "probe.mcap", 1000, 50)  # bytes a step of 1,000 robots takes
        steps = int(args.gigabytes * 1e9 / (probe.stat().st_size / 50))
        logs = [
            ("real episode", real),
            ("at the recompute limit", stretched(real, tmp / "limit.mcap", 10, MAX_RECOMPUTED // 10)),
            ("large", stretched(real, tmp / "large.mcap", 1000, steps)),
        ]
        rows = []
        for name, path in logs:
            mb, seconds, code = inspect_peak(path)
            rows.append((name, path.stat().st_size / 1e6, mb, seconds, code))
        print("| log | size (MB) | inspect peak memory (MB) | time (s) | exit code |")
        print("|---|---|---|---|---|")
        for name, size, mb, seconds, code in rows:
            print(f"| {name} | {size:,.1f} | {mb:,.0f} | {seconds:.1f} | {code} |")
        print(f"target: the largest log under 500 MB of memory ({rows[-1][2]:,.0f} MB)")


if __name__ == "__main__":
    main()
