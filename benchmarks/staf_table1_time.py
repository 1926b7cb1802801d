"""Wall time of the whole STAF-planned Table-1 reproduction: `stafpipe run staf_planned_train` (training maps, warm
start and PPO for phi + psi) then `stafpipe run staf_table1` (STAF-planned, DGNN and L&F x circle, wedge, line x 50
episodes, the tables and Fig. 4), every step forced, into a temporary output folder (nothing under outputs/ is touched).

Usage: python benchmarks/staf_table1_time.py [--keep DIR]
Target (STAF issue): train + evaluate <= 45 minutes on 2 CPU cores. Takes about that long; prints one row per step.
Note: staf_table1 evaluates the shipped checkpoint, not the one trained here; the training is timed for its cost.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import sys
import tempfile
from pathlib import Path

from stafpipe.pipeline import run_pipeline

STEP_LINE = re.compile(r"^\[(\d+)/(\d+)\] (\S+) \((\S+)\): done in ([0-9.]+) s")


class _Tee(io.TextIOBase):
    """Keeps what the pipeline prints while still showing it."""

    def __init__(self, out) -> None:
        self.out, self.text = out, []

    def write(self, s: str) -> int:
        self.text.append(s)
        return self.out.write(s)


def timed(name: str, root: Path) -> list[tuple[str, str, float]]:
    tee = _Tee(sys.stdout)
    with contextlib.redirect_stdout(tee):
        code = run_pipeline(name, force=True, out_root=root)
    if code != 0:
        raise SystemExit(f"pipeline {name} failed with exit code {code}")
    rows = []
    for line in "".join(tee.text).splitlines():
        match = STEP_LINE.match(line)
        if match:
            rows.append((f"{name}/{match.group(3)}", match.group(4), float(match.group(5))))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--keep", default="", help="Write the runs here instead of a temporary folder.")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep or tmp)
        rows = timed("staf_planned_train", root) + timed("staf_table1", root)
    print("| step | stage | wall (s) |")
    print("|---|---|---|")
    for step, stage, seconds in rows:
        print(f"| {step} | {stage} | {seconds:.1f} |")
    total = sum(r[2] for r in rows)
    print(f"| **total** | | **{total:.0f} s = {total / 60:.1f} min** (target <= 45 min) |")


if __name__ == "__main__":
    main()
