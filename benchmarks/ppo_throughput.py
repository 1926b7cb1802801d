"""Trainer throughput: environment robot-steps per second of PPO rollouts including the policy forward pass, and the
update time per sample, for the DGNN policy on the 10-robot corridor, beside the plain-torch reference: the same
network, the same minibatches and epochs, one forward, a squared-error loss on its outputs, backward and an Adam step,
nothing else (what any trainer of this network must pay; the PPO update's excess over it is our overhead).

Usage: python benchmarks/ppo_throughput.py [--steps 100]
Prints one row per number of batched worlds (B = 4, 16, 64) and the device (CPU, 2 threads), then the rate at which
the update does the network's arithmetic (floating-point operations counted by torch's FlopCounterMode on the
forward and backward passes over each row's own rollout, Adam's few per weight left out) beside two references on
the same device: a 2048 x 2048 matrix product (about what the machine computes at all) and a stack of 64-wide linear
layers, forward and backward (the width of the network's layers, without its gathers, sums and activations).
"""

from __future__ import annotations

import argparse
import time

import torch
from torch.utils.flop_counter import FlopCounterMode

from stafpipe.learning.config import PolicyConfig, TrainPPOConfig
from stafpipe.learning.dgnn import DGNNPolicy
from stafpipe.learning.ppo import teams_of, update
from stafpipe.learning.registry import ADAPTERS
from stafpipe.learning.rollout import collect, gae
from stafpipe.scenario_pool import load_named_scenario, path_and_width
from stafpipe.sensing import SensingConfig
from stafpipe.torch_io import training_device
from stafpipe.world import Worlds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--device", default="cpu", help="where the update runs: cpu, cuda or cuda:N")
    args = parser.parse_args()
    device = training_device(args.device, "--device")
    torch.set_num_threads(2)
    torch.manual_seed(0)
    print(f"update device: {device}; rollouts on the cpu, {torch.get_num_threads()} threads")
    print(
        f"{'worlds':>6} | {'rollout robot-steps/s':>21} | {'update us / sample':>18} | "
        f"{'plain torch us / sample':>23} | {'ratio':>5} | {'overall robot-steps/s':>21}"
    )
    print("-" * 112)
    measure(4, 10, device)  # unprinted: the first update on a GPU pays for CUDA's start (234 us a sample at 4 worlds)
    rates = []
    for b in (4, 16, 64):
        samples, rollout, upd, ref, flops = measure(b, args.steps, device)
        rates.append((b, flops, flops * samples / upd))
        print(
            f"{b:>6} | {samples / rollout:>21,.0f} | {1e6 * upd / samples:>18.1f} | {1e6 * ref / samples:>23.1f} | "
            f"{upd / ref:>5.2f} | {samples / (rollout + upd):>21,.0f}"
        )
    print()
    for b, flops, rate in rates:
        print(f"{b:>6} worlds: {flops / 1e6:.2f} MFLOP a sample; the update computes at {rate / 1e9:.0f} GFLOP/s")
    print(f"a 2048 x 2048 matrix product on {device}: {matmul_rate(device) / 1e9:.0f} GFLOP/s")
    print(
        f"eight 64-wide linear layers, forward and backward, 16,000 rows, on {device}: "
        f"{layers_rate(device) / 1e9:.0f} GFLOP/s"
    )


def measure(b: int, steps: int, device: torch.device) -> tuple[int, float, float, float, float]:
    """(robot-steps, rollout s, PPO update s, plain-torch update s, update FLOP a sample) of one iteration of b
    corridor worlds."""
    corridor = load_named_scenario("corridor")
    path, eta = path_and_width(corridor)
    tc = TrainPPOConfig(worlds=b, episode_steps=steps)
    policy = DGNNPolicy(PolicyConfig())
    opt = torch.optim.Adam(policy.parameters(), lr=tc.lr)
    worlds = Worlds([corridor] * b, SensingConfig())
    obs = worlds.reset(list(range(b)))
    adapter = ADAPTERS["dgnn"](tc.policy, tc.reward, None, 2.0)
    adapter.begin(teams_of([(corridor, path, eta)] * b, worlds))
    start = time.perf_counter()
    ro, _ = collect(policy, adapter, worlds, obs, tc, 0.3)
    rollout = time.perf_counter() - start
    adv, ret = gae(ro.rewards, ro.values, ro.last_value, tc.gamma, tc.gae_lambda)
    start = time.perf_counter()
    update(policy, opt, ro, adv, ret, tc, torch.Generator().manual_seed(0), device)
    upd = time.perf_counter() - start
    return ro.rewards.numel(), rollout, upd, plain_update(policy, ro, tc, device), update_flops(policy, ro, tc)


def update_flops(policy: DGNNPolicy, ro, tc: TrainPPOConfig) -> float:
    """Floating-point operations of the update per robot-sample, counted on this rollout's own samples: one forward
    and backward pass over them all (on the CPU: the messages of the pairs within the radius alone), times the
    epochs."""
    t, b = ro.rewards.shape[:2]
    own, edge, mask = (x.reshape(t * b, *x.shape[2:]) for x in (ro.own, ro.edge, ro.mask))

    def step() -> None:
        mean, value = policy(own, edge, mask)
        (mean.square().mean() + value.square().mean()).backward()

    flops = counted_flops(step)
    policy.zero_grad()
    return tc.epochs * flops / ro.rewards.numel()


def counted_flops(run) -> int:
    """Floating-point operations torch's FlopCounterMode counts in one call of `run` (matrix products and the like)."""
    with FlopCounterMode(display=False) as counter:
        run()
    return counter.get_total_flops()


def best_seconds(run, device: torch.device, tries: int) -> float:
    """The shortest of `tries` timed calls of `run` (waiting for a GPU to finish each)."""
    best = float("inf")
    for _ in range(tries):
        start = time.perf_counter()
        run()
        if device.type == "cuda":
            torch.cuda.synchronize()
        best = min(best, time.perf_counter() - start)
    return best


def matmul_rate(device: torch.device) -> float:
    """FLOP/s of a 2048 x 2048 float32 matrix product, the best of five."""
    a = torch.randn(2048, 2048, device=device)
    return counted_flops(lambda: a @ a) / best_seconds(lambda: a @ a, device, 5)


def layers_rate(device: torch.device) -> float:
    """FLOP/s of forward and backward through eight 64 -> 64 linear layers on 16,000 rows, the best of ten (counted as
    the update is: the input needs no gradient, so the first layer's backward is one product, not two)."""
    layers = torch.nn.Sequential(*(torch.nn.Linear(64, 64) for _ in range(8))).to(device)
    x = torch.randn(16_000, 64, device=device)

    def run() -> None:
        layers(x).sum().backward()

    return counted_flops(run) / best_seconds(run, device, 10)


def plain_update(policy: DGNNPolicy, ro, tc: TrainPPOConfig, device: torch.device) -> float:
    """Seconds for tc.epochs x tc.minibatches plain steps of the same network on the same samples (module docstring)."""
    t, b = ro.rewards.shape[:2]
    policy.to(device)
    own, edge, mask = (x.reshape(t * b, *x.shape[2:]).to(device) for x in (ro.own, ro.edge, ro.mask))
    act_target = ro.actions.reshape(t * b, *ro.actions.shape[2:]).to(device)
    value_target = ro.values.reshape(t * b, -1).to(device)
    opt = torch.optim.Adam(policy.parameters(), lr=tc.lr)
    size = t * b // tc.minibatches
    start = time.perf_counter()
    for _ in range(tc.epochs):
        order = torch.randperm(t * b)
        for k in range(tc.minibatches):
            mb = order[k * size : (k + 1) * size].to(device)
            mean, value = policy(own[mb], edge[mb], mask[mb])
            loss = ((mean - act_target[mb]) ** 2).mean() + ((value - value_target[mb]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
    if device.type == "cuda":
        torch.cuda.synchronize()
    seconds = time.perf_counter() - start
    policy.cpu()
    return seconds


if __name__ == "__main__":
    main()
