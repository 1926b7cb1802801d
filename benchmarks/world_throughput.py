"""Robot-steps per second of the batched pymunk world with the full observation, 10-robot corridor.

Usage: python benchmarks/world_throughput.py [--steps 200]
Prints a table for 1, 64 and 1024 worlds (target: >= 300k robot-steps/s at 64 worlds on a 2-core machine). With the
`bench` extra installed (`pip install ".[bench]"`) VMAS's `navigation` scenario (10 agents, its default lidar
observation, CPU) is measured beside it at 1 and 64 worlds; 1024 VMAS worlds take minutes and are skipped.
"""

from __future__ import annotations

import argparse
import importlib.util
import time

from stafpipe.paths import conf_dir
from stafpipe.scenario import build_scenario, load_scenario_file
from stafpipe.world import Worlds

ROBOTS = 10


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


def measure_vmas(batch: int, steps: int) -> float:
    """Robot-steps/s of VMAS's navigation scenario with 10 agents and zero actions on the CPU."""
    import torch
    import vmas

    env = vmas.make_env("navigation", num_envs=batch, device="cpu", continuous_actions=True, n_agents=ROBOTS, seed=0)
    env.reset()
    actions = [torch.zeros(batch, 2) for _ in range(ROBOTS)]
    for _ in range(3):
        env.step(actions)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(actions)
    return batch * ROBOTS * steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    with_vmas = importlib.util.find_spec("vmas") is not None
    header = f"{'worlds':>7} | {'robot-steps/s':>14} | {'ms / batch step':>15}"
    print(header + (f" | {'VMAS robot-steps/s':>18}" if with_vmas else ""))
    print("-" * len(header) + ("-" * 21 if with_vmas else ""))
    for batch in (1, 64, 1024):
        rate, ms = measure(batch, max(10, args.steps // (1 + batch // 64)))
        row = f"{batch:>7} | {rate:>14,.0f} | {ms:>15.2f}"
        if with_vmas:
            row += f" | {measure_vmas(batch, 30):>18,.0f}" if batch <= 64 else f" | {'(skipped)':>18}"
        print(row)
    if not with_vmas:
        print("(install the `bench` extra to compare with VMAS navigation)")


if __name__ == "__main__":
    main()
