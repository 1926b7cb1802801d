"""Batched against one-at-a-time evaluation: the evaluation steps of `stafpipe run staf_table1` (STAF with two and with
m = auto subteams, DGNN, L&F; corridor; circle, wedge, line), each run with `eval.batch=1` (one episode at a time, as
every eval ran before batching) and with the default batch, into a temporary folder. Prints one row per step with both
wall times, the speed-up, and whether the two results tables are identical.

Usage: python benchmarks/eval_batch_time.py [--episodes 50] [--batch 0] [--steps staf-circle,lf-line]
Target (harness issue): the whole evaluation >= 5x faster batched, results equal for equal seeds. With 50 episodes it
takes about 15 minutes on 2 cores (most of it the one-at-a-time runs).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

from stafpipe.geometry import _SHARED
from stafpipe.launch import launch
from stafpipe.paths import pipelines_dir


def timed_eval(overrides: list[str], run_dir: Path) -> tuple[float, pd.DataFrame]:
    _SHARED.clear()  # each run computes its scenario's grid and paths itself, as a new process would
    start = time.perf_counter()
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        code = launch("eval", [*overrides, "eval.log_episodes=true", f"hydra.run.dir={run_dir}"])
    if code != 0:
        raise SystemExit(f"eval {' '.join(overrides)} failed with exit code {code}")
    return time.perf_counter() - start, pd.read_parquet(run_dir / "results.parquet")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--episodes", type=int, default=50, help="episodes per step (staf_table1: 50)")
    parser.add_argument("--batch", type=int, default=0, help="eval.batch of the batched runs (0: the default)")
    parser.add_argument("--steps", default="", help="comma-separated step names (default: every eval step)")
    args = parser.parse_args()
    spec = yaml.safe_load((pipelines_dir() / "staf_table1.yaml").read_text())
    steps = [s for s in spec["steps"] if s["stage"] == "eval"]
    if args.steps:
        steps = [s for s in steps if s["name"] in args.steps.split(",")]
    print(f"| step | one at a time (s) | batched, eval.batch={args.batch} (s) | speed-up | results equal |")
    print("|---|---|---|---|---|")
    total_one = total_batched = 0.0
    all_equal = True
    with tempfile.TemporaryDirectory() as tmp:
        for step in steps:
            overrides = [o for o in step["overrides"] if not o.startswith("eval.episodes=")]
            overrides.append(f"eval.episodes={args.episodes}")
            one, df_one = timed_eval([*overrides, "eval.batch=1"], Path(tmp) / step["name"] / "one")
            batched, df_batched = timed_eval([*overrides, f"eval.batch={args.batch}"], Path(tmp) / step["name"] / "b")
            equal = df_one.equals(df_batched)
            all_equal &= equal
            total_one += one
            total_batched += batched
            print(f"| {step['name']} | {one:.1f} | {batched:.1f} | {one / batched:.2f}x | {'yes' if equal else 'NO'} |")
    print(
        f"| **total** | **{total_one:.0f}** | **{total_batched:.0f}** | **{total_one / total_batched:.2f}x** "
        f"(target >= 5x) | {'yes' if all_equal else 'NO'} |"
    )


if __name__ == "__main__":
    main()
