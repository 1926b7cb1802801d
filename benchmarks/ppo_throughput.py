"""Trainer throughput: environment robot-steps per second of PPO rollouts including the policy forward pass, and the
update time per sample, for the DGNN policy on the 10-robot corridor, beside the plain-torch reference: the same
network, the same minibatches and epochs, one forward, a squared-error loss on its outputs, backward and an Adam step,
nothing else (what any trainer of this network must pay; the PPO update's excess over it is our overhead).

Usage: python benchmarks/ppo_throughput.py [--steps 100]
       python benchmarks/ppo_throughput.py --workers 1 2 [--worlds 64] [--iterations 6] [--project 16]
Prints one row per number of batched worlds (B = 4, 16, 64) and the device (CPU, 2 threads), then the rate at which
the update does the network's arithmetic (floating-point operations counted by torch's FlopCounterMode on the
forward and backward passes over each row's own rollout, Adam's few per weight left out) beside two references on
the same device: a 2048 x 2048 matrix product (about what the machine computes at all) and a stack of 64-wide linear
layers, forward and backward (the width of the network's layers, without its gathers, sums and activations).

With `--workers`, the whole trainer instead (`stafpipe train-ppo`, DGNN on the corridor, `train_ppo.workers`, DD-PPO):
one worker with one torch thread (what a bit-reproducible run uses, docs/decisions.md) and with a thread per core,
then each larger count of workers with the cores shared out (threads = cores // workers); the overall robot-steps/s
(the median over the iterations after the first, which pays for warming up) with where an iteration's time goes
(the rollout; the update, and of it the gradient exchange, waiting for the slowest worker included), the speed-up
over both one-worker rows, and with `--project N` a row for N workers computed from the measured parts.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import torch
from torch.utils.flop_counter import FlopCounterMode

from stafpipe.learning.config import PolicyConfig, TrainPPOConfig
from stafpipe.learning.distributed import joined, launch, leave
from stafpipe.learning.ppo import teams_of, update
from stafpipe.learning.rollout import collect, gae
from stafpipe.methods.dgnn.network import DGNNPolicy
from stafpipe.registry import adapter_class
from stafpipe.scenario_pool import load_named_scenario, path_and_width
from stafpipe.sensing import SensingConfig
from stafpipe.torch_io import training_device
from stafpipe.world import Worlds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--device", default="cpu", help="where the update runs: cpu, cuda or cuda:N")
    parser.add_argument("--workers", type=int, nargs="*", help="train-ppo.workers counts to compare (the trainer)")
    parser.add_argument("--worlds", type=int, default=64, help="with --workers: worlds per iteration")
    parser.add_argument("--iterations", type=int, default=6, help="with --workers: iterations per run")
    parser.add_argument("--project", type=int, default=0, help="with --workers: a projected row for this many")
    args = parser.parse_args()
    if args.workers:
        compare_workers(args.workers, args.worlds, args.iterations, args.steps, args.project)
        return
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
    adapter = adapter_class("dgnn")(tc.policy, tc.reward, None, 2.0)
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


def _trainer_run(workers: int, threads: int, worlds: int, steps: int, iterations: int) -> dict[str, float]:
    """One `stafpipe train-ppo` run (DGNN, corridor, seed 0): the medians over its iterations after the first (which
    pays for warming up) of the rollout, update and gradient-exchange seconds and the overall robot-steps/s."""
    with tempfile.TemporaryDirectory() as tmp:
        words = [
            f"train_ppo.workers={workers}",
            f"train_ppo.threads={threads}",
            f"train_ppo.worlds={worlds}",
            f"train_ppo.episode_steps={steps}",
            f"train_ppo.iterations={iterations}",
            "train_ppo.eval_every=0",
            f"train_ppo.checkpoint_every={iterations}",
            f"hydra.run.dir={tmp}/run",
        ]
        subprocess.run([sys.executable, "-m", "stafpipe", "train-ppo", *words], check=True, capture_output=True)
        rows = pd.read_csv(Path(tmp) / "run" / "learning_curves.csv")
    samples = rows["robot_steps"].diff().fillna(rows["robot_steps"])
    rows = rows.assign(rollout_seconds=samples / rows["charts/rollout_fps"]).iloc[1:]
    exchange = rows["charts/exchange_seconds"] if "charts/exchange_seconds" in rows else pd.Series([0.0])
    return {
        "rollout": statistics.median(rows["rollout_seconds"]),
        "update": statistics.median(rows["charts/update_seconds"]),
        "exchange": statistics.median(exchange),
        "rate": statistics.median(rows["charts/fps"]),
        "samples": statistics.median(samples),
    }


def compare_workers(counts: list[int], worlds: int, iterations: int, steps: int, project: int) -> None:
    """`stafpipe train-ppo` runs for one worker with one thread and with every core's, then for each larger count of
    workers with the cores shared out; the same worlds and seed. Prints the table, and with `project` a row for that
    many workers computed from the measured parts (labelled as such)."""
    cores = os.cpu_count() or 1
    runs = [(1, 1), (1, cores)] + [(n, max(1, cores // n)) for n in counts if n > 1]
    print(f"train-ppo, DGNN on the corridor, {worlds} worlds x {steps} steps, {iterations} iterations, {cores} cores")
    print(
        f"{'workers':>7} | {'threads each':>12} | {'rollout s':>9} | {'update s':>8} | {'of it exchange s':>16} | "
        f"{'overall robot-steps/s':>21} | {'x (1 w, 1 thread)':>17} | {f'x (1 w, {cores} threads)':>18}"
    )
    print("-" * 130)
    got = {}
    for n, threads in dict.fromkeys(runs):
        got[n, threads] = m = _trainer_run(n, threads, worlds, steps, iterations)
        _row(str(n), threads, m, got[1, 1]["rate"], got.get((1, cores), m)["rate"])
    if project > 1:
        # the parts of one iteration at `project` workers, one core each: the rollout of worlds / project worlds
        # measured in one process; the one-thread update divided by the workers; the exchange, one all-reduce of the
        # network's gradient per minibatch, at the latency measured between 2 processes times (project - 1) (a ring
        # all-reduce takes 2 (N - 1) steps, 2 at N = 2); no waiting for a slower worker counted
        share = _trainer_run(1, 1, max(1, worlds // project), steps, iterations)
        per_call = launch(2, _all_reduce_seconds, sum(p.numel() for p in DGNNPolicy(PolicyConfig()).parameters()))
        calls = TrainPPOConfig().epochs * TrainPPOConfig().minibatches
        parts = {"rollout": share["rollout"], "exchange": per_call * calls * (project - 1)}
        parts["update"] = got[1, 1]["update"] / project + parts["exchange"]
        parts["rate"] = got[1, 1]["samples"] / (parts["rollout"] + parts["update"])
        print(f"projected from: one all-reduce of the gradient between 2 processes {1e3 * per_call:.1f} ms")
        _row(f"{project}*", 1, parts, got[1, 1]["rate"], got.get((1, cores), parts)["rate"])


def _all_reduce_seconds(size: int) -> float:
    """The mean time of one all-reduce of `size` floats among the launched processes (gloo), after a first one."""
    import torch.distributed as dist

    joined()
    x = torch.zeros(size)
    dist.all_reduce(x)
    start = time.perf_counter()
    for _ in range(50):
        dist.all_reduce(x)
    seconds = (time.perf_counter() - start) / 50
    leave()
    return seconds


def _row(name: str, threads: int, m: dict[str, float], one: float, many: float) -> None:
    print(
        f"{name:>7} | {threads:>12} | {m['rollout']:>9.2f} | {m['update']:>8.2f} | {m['exchange']:>16.2f} | "
        f"{m['rate']:>21,.0f} | {m['rate'] / one:>16.2f}x | {m['rate'] / many:>17.2f}x"
    )


if __name__ == "__main__":
    main()
