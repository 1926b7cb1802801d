"""A directory of generated maps evaluated as one sweep (`stafpipe eval -m scenario.path=DIR`): one job after another
(Hydra's basic launcher) against `--workers` processes (`hydra/launcher=local`, joblib), each as a fresh
`stafpipe` process. Prints the wall times, the ratio and whether every job's results table is the same.

Usage: python benchmarks/eval_maps_parallel.py [--maps 40] [--workers 2] [--method dgnn] [--episodes 5]
Target (scale-out issue): with 2 workers at most 0.6x the serial time, the same results.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd


def stafpipe(args: list[str], cwd: Path) -> float:
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "stafpipe", *args], cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"stafpipe {' '.join(args)} failed:\n{done.stderr[-2000:]}")
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--maps", type=int, default=40)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--method", default="dgnn")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--seed", type=int, default=4711, help="the maps' generate-maps seed")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        stafpipe(
            ["generate-maps", f"seed={args.seed}", f"maps.count={args.maps}", f"hydra.run.dir={root / 'gen'}"], root
        )
        sweep = ["eval", "-m", f"method={args.method}", f"scenario.path={root / 'gen' / 'maps'}"]
        sweep.append(f"eval.episodes={args.episodes}")
        serial = stafpipe([*sweep, f"hydra.sweep.dir={root / 'serial'}"], root)
        local = ["hydra/launcher=local", f"hydra.launcher.n_jobs={args.workers}", f"hydra.sweep.dir={root / 'par'}"]
        parallel = stafpipe([*sweep, *local], root)
        same = all(
            pd.read_parquet(root / "serial" / str(j) / "results.parquet").equals(
                pd.read_parquet(root / "par" / str(j) / "results.parquet")
            )
            for j in range(args.maps)
        )
    print(f"| maps | method | episodes per map | serial (s) | {args.workers} workers (s) | ratio | same results |")
    print("|---|---|---|---|---|---|---|")
    print(
        f"| {args.maps} | {args.method} | {args.episodes} | {serial:.1f} | {parallel:.1f} | {parallel / serial:.2f} "
        f"(target <= 0.6) | {'yes' if same else 'NO'} |"
    )


if __name__ == "__main__":
    main()
