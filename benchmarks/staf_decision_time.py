"""Decision time of STAF for one control step (plan or rules + deep graph cut when it splits + GNN + policy), for
STAF-planned (`method=staf_planned`) and the paper's STAF (`method=staf`, its 10-robot rows).

Usage: python benchmarks/staf_decision_time.py [--repeats 30] [--episodes 40] [--maps corridor doorway ...]
       [--ensemble B.pt C.pt]  (the 10-robot rows with `method.ensemble`: one forward pass more per member;
       `--ensemble` alone: the shipped `staf_planned.pt` by itself)
Targets (STAF issue): 10 robots <= 1 ms per step, 1,000 robots <= 50 ms. One torch thread, the shipped policy (its two
runs averaged, as `method=staf_planned` runs it) and deep graph cut. 10 robots: `method=staf_planned`'s own act() on the
corridor (dense features from the harness' observation), timed per step over whole episodes; the split step (which runs
the cut) is reported apart. 1,000 robots: a 40 x 25 grid of robots (1 m spacing) heading through a 1 km corridor,
edge-list features (k-d tree within 2 m) and the edge-list forward pass; sensing (the harness' observation) is not part
of the decision and is excluded.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np
import torch

from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.controllers.staf import StafController, StafMethodConfig
from stafpipe.controllers.staf_plan import StafPlan
from stafpipe.episode import episode_context
from stafpipe.geometry import Geometry
from stafpipe.highlevel.infer import divider
from stafpipe.learning.checkpoint import ensemble_paths, load_policy
from stafpipe.learning.features import staf_pairs
from stafpipe.scenario import build_scenario
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import Worlds


def ten_robots(
    episodes: int, name: str = "corridor", ensemble: list[str] | None = None, method: str = "staf_planned"
) -> tuple[float, float, float]:
    """(median ms per step, 99th percentile ms per step, median ms of the split step) over episodes on map `name`:
    one split step per episode, so several episodes keep a single slow sample from deciding it. `method`: staf_planned
    (its plan) or staf (the paper's rules, methods/staf)."""
    sc = load_named_scenario(name)
    geometry = Geometry(sc)
    ctx, path = episode_context(sc, geometry, SensingConfig(), 0.3, 0.1)
    if method == "staf":
        from stafpipe.controllers import make_controller
        from stafpipe.methods.staf.method import StafConfig

        ctrl = make_controller(StafConfig(ensemble=ensemble))
    else:
        ctrl = StafController(StafMethodConfig(ensemble=ensemble))
    worlds = Worlds([sc], SensingConfig())
    from stafpipe.controllers.base import TeamInfo

    times, split_ms = [], []
    for _ in range(episodes):
        obs = worlds.reset([0]).world(0)
        ctrl.reset(TeamInfo(sc, obs.position.copy(), worlds.goal[0].copy(), sc.template(), path, ctx.passage_width))
        for _ in range(400):
            start = time.perf_counter()
            action = ctrl.act(obs)
            elapsed = 1000 * (time.perf_counter() - start)
            events = [e.kind for e in ctrl.drain_events()]
            (split_ms if "split" in events else times).append(elapsed)
            obs = worlds.step(action[None])[0].world(0)
    return statistics.median(times), float(np.percentile(times, 99)), statistics.median(split_ms)


def thousand_robots(repeats: int, ensemble: list[str] | None = None) -> tuple[float, float, float, int]:
    """(plan ms, features ms, network ms, edges) for 1,000 robots; the network time is every run's (`ensemble` as
    `method.ensemble` reads it)."""
    base = load_named_scenario("corridor")
    spec = dataclasses.replace(
        base.spec,
        world=dataclasses.replace(base.spec.world, xmin=-50, xmax=1050, ymin=-50, ymax=60),
        obstacles=[],
        team=dataclasses.replace(base.spec.team, formation="square", n=1000, start=[0.0, 6.0], goal=[1000.0, 6.0]),
    )
    sc = build_scenario(spec)
    policies = [load_policy(path, "staf_planned")[0] for path in ["", *ensemble_paths("", ensemble, "staf_planned")]]
    policy = policies[0]
    template = sc.template()
    pos = template + [0.0, 6.0]
    goal = template + [1000.0, 6.0]
    plan = StafPlan(PlanConfig(), sc, template, goal, np.array([[0.0, 6.0], [1000.0, 6.0]]), 50.0, divider())
    vel = np.zeros_like(pos)
    heading = np.zeros(len(pos))
    obstacle = np.full_like(pos, 10.0)
    plan_ms, feat_ms, net_ms, edges = [], [], [], 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        target = plan.step(pos, 0.1)
        t1 = time.perf_counter()
        own, receiver, diff = staf_pairs(
            pos, vel, heading, obstacle, target, plan.labels, policy.cfg.goal_clip, 2.0, 2.0
        )
        t2 = time.perf_counter()
        with torch.inference_mode():
            x = (torch.from_numpy(own), torch.from_numpy(receiver), torch.from_numpy(diff))
            torch.stack([p.act_sparse(*x) for p in policies]).mean(0)
        t3 = time.perf_counter()
        plan_ms.append(1000 * (t1 - t0)), feat_ms.append(1000 * (t2 - t1)), net_ms.append(1000 * (t3 - t2))
        edges = len(receiver)
    return statistics.median(plan_ms), statistics.median(feat_ms), statistics.median(net_ms), edges


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--episodes", type=int, default=40, help="10-robot episodes timed per map")
    parser.add_argument("--maps", nargs="+", default=["corridor"], help="built-in maps of the 10-robot rows")
    parser.add_argument(
        "--ensemble", nargs="*", default=None, help="policy.pt files averaged with staf_planned.pt (none: it alone)"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = [(name, *ten_robots(args.episodes, name, args.ensemble)) for name in args.maps]
    paper = [(name, *ten_robots(args.episodes, name, [], "staf")) for name in args.maps]
    plan, feat, net, edges = thousand_robots(args.repeats, args.ensemble)
    print("| team | per step (median) | 99th percentile step | split step (cut, median) | target |")
    print("|---|---|---|---|---|")
    runs = 1 + len(ensemble_paths("", args.ensemble, "staf_planned"))
    what = f"method=staf_planned, {runs} run{'s' if runs > 1 else ''}"
    for name, median, worst, split in rows:
        print(f"| 10 robots, {name}, {what} act() | {median:.2f} ms | {worst:.2f} ms | {split:.2f} ms | <= 1 ms |")
    for name, median, worst, split in paper:
        print(f"| 10 robots, {name}, method=staf act() | {median:.2f} ms | {worst:.2f} ms | {split:.2f} ms | <= 1 ms |")
    print(
        f"| 1,000 robots ({edges:,} directed edges): plan {plan:.1f} + features {feat:.1f} + network {net:.1f} | "
        f"{plan + feat + net:.1f} ms | - | - | <= 50 ms |"
    )


if __name__ == "__main__":
    main()
