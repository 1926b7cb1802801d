"""Robot-steps per second of the batched pymunk world with the full observation, 10-robot corridor.

Usage: python benchmarks/world_throughput.py [--steps 200]
Prints a table for 1, 64 and 1024 worlds (target: >= 300k robot-steps/s at 64 worlds on a 2-core machine).
With the `bench` extra (vmas) installed it could be compared with VMAS navigation; that comparison is not wired yet.
"""

from __future__ import annotations

import argparse
import time

from stafpipe.paths import conf_dir
from stafpipe.scenario import build_scenario, load_scenario_file
from stafpipe.world import Worlds


def measure(batch: int, steps: int) -> tuple[float, float]:
    """(robot-steps/s, ms per batch step) of `steps` steps of `batch` corridor worlds."""
    sc = build_scenario(load_scenario_file(conf_dir() / "scenario" / "corridor.yaml"))
    worlds = Worlds([sc] * batch)
    worlds.reset(list(range(batch)))
    for _ in range(5):  # warm-up
        worlds.step(worlds.goal - worlds.pos)
    start = time.perf_counter()
    for _ in range(steps):
        worlds.step(worlds.goal - worlds.pos)
    elapsed = time.perf_counter() - start
    return batch * sc.spec.team.n * steps / elapsed, 1000 * elapsed / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    print(f"{'worlds':>7} | {'robot-steps/s':>14} | {'ms / batch step':>15}")
    print(f"{'-' * 7}-|-{'-' * 14}-|-{'-' * 15}")
    for batch in (1, 64, 1024):
        rate, ms = measure(batch, max(10, args.steps // (1 + batch // 64)))
        print(f"{batch:>7} | {rate:>14,.0f} | {ms:>15.2f}")


if __name__ == "__main__":
    main()
