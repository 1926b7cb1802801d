"""Throughput of the multi-agent environment API (stafpipe.marl_env) beside the native batched world.

Usage: python benchmarks/marl_env_throughput.py [--worlds 64] [--steps 200]
Prints robot-steps/s of (1) the native world (`Worlds.step` with random commands, observation included), (2) the
batched API (`BatchedTeamEnv.step`: the world plus the method's features and reward, what a trainer consumes) and
(3) the PettingZoo ParallelEnv (one world, dicts per agent), on the 10-robot corridor, one thread, and the ratio of
(2) to (1) (target >= 50 % at 64 worlds).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from stafpipe.learning.rollout import commands
from stafpipe.marl_env import BatchedTeamEnv, parallel_env


def rate(step, steps: int, robots: int) -> float:
    step()
    began = time.perf_counter()
    for _ in range(steps):
        step()
    return steps * robots / (time.perf_counter() - began)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=64)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--method", default="dgnn")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    env = BatchedTeamEnv("corridor", worlds=args.worlds, method=args.method, episode_steps=10**9)
    env.reset(0)
    shape = (args.worlds, env.n, 2)
    native = env.worlds
    native_rate = rate(
        lambda: native.step(commands(rng.uniform(-1, 1, shape), native.heading, 1.0)), args.steps, args.worlds * env.n
    )
    env.reset(0)
    api_rate = rate(lambda: env.step(rng.uniform(-1, 1, shape)), args.steps, args.worlds * env.n)
    pz = parallel_env(scenario="corridor", method=args.method, episode_steps=10**9)
    pz.reset(seed=0)
    space = pz.action_space("robot_0")
    pz_rate = rate(lambda: pz.step({a: space.sample() for a in pz.agents}), args.steps // 2, env.n)
    print(f"corridor, {env.n} robots, method={args.method}, one thread")
    print("| interface | worlds | robot-steps/s | vs native |")
    print("|---|---|---|---|")
    print(f"| native Worlds.step | {args.worlds} | {native_rate:,.0f} | 100 % |")
    print(
        f"| BatchedTeamEnv.step (features + reward) | {args.worlds} | {api_rate:,.0f} | {100 * api_rate / native_rate:.0f} % |"  # noqa: E501
    )
    print(f"| PettingZoo ParallelEnv.step | 1 | {pz_rate:,.0f} | {100 * pz_rate / native_rate:.0f} % |")


if __name__ == "__main__":
    main()
