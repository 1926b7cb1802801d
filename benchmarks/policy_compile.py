"""Does `torch.compile` make the trainer's network cheaper on the CPU? One minibatch step of each policy (forward,
a squared-error loss on the action mean and the value, backward, Adam), eager against compiled (inductor, the
default mode), in microseconds per robot-sample: the quantity `benchmarks/ppo_throughput.py` calls the plain-torch
reference, of which the PPO update does `train_ppo.epochs` per sample.

Usage: python benchmarks/policy_compile.py [--reps 20] [--minibatch 400 1600]
Prints one row per policy and minibatch (world-steps of 10 robots; 400 is 16 worlds x 100 steps / 4 minibatches,
1,600 the trainer's default 16 worlds x 400 steps / 4), 2 threads. Compiling needs a C++ compiler; its one-off time
is printed apart and not counted in the per-sample figure.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import torch

from stafpipe.learning.config import PolicyConfig
from stafpipe.learning.features import EDGE, OWN, STAF_EDGE, STAF_OWN
from stafpipe.learning.policy_net import PolicyNet
from stafpipe.learning.staf_net import StafPolicy
from stafpipe.methods.dgnn.network import DGNNPolicy

ROBOTS = 10


def step_cost(
    policy: PolicyNet, forward: Callable, sizes: tuple[int, int], minibatch: int, reps: int
) -> tuple[float, float]:
    """(us per robot-sample of one step, seconds of the first three steps: compiling, for a compiled forward)."""
    gen = torch.Generator().manual_seed(0)
    own = torch.randn(minibatch, ROBOTS, sizes[0], generator=gen)
    edge = torch.randn(minibatch, ROBOTS, ROBOTS, sizes[1], generator=gen)
    mask = torch.rand(minibatch, ROBOTS, ROBOTS, generator=gen) > 0.2
    opt = torch.optim.Adam(policy.parameters(), lr=1e-4)

    def one() -> None:
        mean, value = forward(own, edge, mask)
        loss = (mean**2).mean() + (value**2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    start = time.perf_counter()
    for _ in range(3):
        one()
    first = time.perf_counter() - start
    start = time.perf_counter()
    for _ in range(reps):
        one()
    return 1e6 * (time.perf_counter() - start) / reps / (minibatch * ROBOTS), first


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--minibatch", type=int, nargs="+", default=[400, 1600])
    args = parser.parse_args()
    torch.set_num_threads(2)
    print(f"torch {torch.__version__}, cpu, {torch.get_num_threads()} threads")
    print(f"{'policy':>6} | {'minibatch':>9} | {'eager us/sample':>15} | {'compiled us/sample':>18} | {'compile s':>9}")
    print("-" * 70)
    for name, make, sizes in (("dgnn", DGNNPolicy, (OWN, EDGE)), ("staf_planned", StafPolicy, (STAF_OWN, STAF_EDGE))):
        for mb in args.minibatch:
            torch.manual_seed(0)
            eager = make(PolicyConfig())
            e, _ = step_cost(eager, eager, sizes, mb, args.reps)
            torch.manual_seed(0)
            compiled = make(PolicyConfig())
            c, first = step_cost(compiled, torch.compile(compiled), sizes, mb, args.reps)
            print(f"{name:>6} | {mb:>9} | {e:>15.1f} | {c:>18.1f} | {first:>9.1f}")


if __name__ == "__main__":
    main()
