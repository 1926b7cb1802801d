"""Does the STAF network brake where its teacher would? The network against its warm-start teacher on the network's
own states.

Usage: python benchmarks/staf_braking.py [--maps corridor doorway MAP.yaml DIR ...] [--episodes 2] [--checkpoint P]
For each map, STAF (the shipped policy, or `--checkpoint`) drives its episodes; at every step the `avoiding` teacher's
command for the same observation and plan targets is computed beside the network's. A robot within `--near` m of a
wall (or of another robot) "under-brakes" when its command approaches that wall (robot) more than `--excess` m/s
faster than the teacher's would. Prints one row per map: near-wall steps, of them under-braking, the same for robots,
and contacts. A fit diagnostic for the low level (docs/staf_planned.md), not a speed or success benchmark.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from stafpipe.config.schema import EvalConfig
from stafpipe.controllers.base import TeamInfo
from stafpipe.controllers.staf import StafController, StafMethodConfig
from stafpipe.episode import episode_context
from stafpipe.geometry import Geometry
from stafpipe.learning.rollout import commands
from stafpipe.learning.teachers import teacher_actions
from stafpipe.metrics import matched_goal_distance
from stafpipe.scenario import Scenario, build_scenario, load_scenario_file
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import Observation, SensingConfig
from stafpipe.world import Worlds

EVAL = EvalConfig()  # the evaluation's defaults: goal tolerance and CFI margin


def scenarios(names: list[str]) -> list[Scenario]:
    """Built-in names, scenario files and directories of them (every `*.yaml` inside)."""
    out = []
    for name in names:
        path = Path(name)
        if path.is_dir():
            out += [build_scenario(load_scenario_file(p)) for p in sorted(path.glob("*.yaml"))]
        elif path.suffix == ".yaml":
            out.append(build_scenario(load_scenario_file(path)))
        else:
            out.append(load_named_scenario(name))
    return out


def approach(command: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """(n,) speed of each command along the unit vectors `towards` (n, 2)."""
    return np.einsum("ij,ij->i", command, towards)


def count(sc: Scenario, ctrl: StafController, episodes: int, near: float, excess: float) -> tuple[int, ...]:
    sensing = SensingConfig()
    ctx, path = episode_context(sc, Geometry(sc), sensing, EVAL.goal_tolerance, EVAL.cfi_margin)
    r, top, gain = sc.spec.robot.radius, sc.spec.robot.max_speed, ctrl.cfg.proportional_gain
    drive = sc.spec.robot.drive
    wall = wall_under = robots = robots_under = contacts = 0
    for episode in range(episodes):
        worlds = Worlds([sc], sensing)
        obs = worlds.reset([episode]).world(0)
        ctrl.reset(TeamInfo(sc, obs.position.copy(), worlds.goal[0].copy(), sc.template(), path, ctx.passage_width))
        for _ in range(int(sc.spec.time_limit / worlds.cfg.control_dt)):
            net = ctrl.act(obs)
            batch = Observation(*(np.asarray(x)[None] for x in obs))
            aim = (ctrl.targets - obs.position)[None]
            teacher = commands(teacher_actions("avoiding", aim, batch, r, top, gain, drive), batch.heading, top)[0]
            to_wall = obs.obstacle / np.maximum(np.linalg.norm(obs.obstacle, axis=1, keepdims=True), 1e-9)
            close = obs.obstacle_distance < near
            faster = approach(net, to_wall) - approach(teacher, to_wall) > excess
            wall, wall_under = wall + int(close.sum()), wall_under + int((close & faster).sum())
            dist = np.linalg.norm(obs.rel_position, axis=-1) + np.eye(len(net)) * 1e9  # [i, j]: p_j - p_i
            to_robot = obs.rel_position[np.arange(len(net)), dist.argmin(axis=1)] / dist.min(axis=1)[:, None]
            close = dist.min(axis=1) - 2 * r < near
            faster = approach(net, to_robot) - approach(teacher, to_robot) > excess
            robots, robots_under = robots + int(close.sum()), robots_under + int((close & faster).sum())
            step, events = worlds.step(net[None])
            contacts += len(events[0])
            obs = step.world(0)
            if (matched_goal_distance(worlds.pos[0], worlds.goal[0]) < EVAL.goal_tolerance).all():
                break  # every goal slot taken: the harness' success
    return wall, wall_under, robots, robots_under, contacts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--maps", nargs="+", default=["corridor", "doorway", "narrowing", "bollards"])
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--checkpoint", default="", help="a STAF policy checkpoint (default: the shipped one)")
    parser.add_argument("--near", type=float, default=0.2, help="a wall or robot this close (m, surface to surface)")
    parser.add_argument("--excess", type=float, default=0.3, help="approach this much faster than the teacher (m/s)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    ctrl = StafController(StafMethodConfig(checkpoint=args.checkpoint, allow_mismatch=True))
    print("| map | team | near-wall steps | under-braking | near-robot steps | under-braking | contacts |")
    print("|---|---|---|---|---|---|---|")
    for sc in scenarios(args.maps):
        wall, wall_under, robots, robots_under, contacts = count(sc, ctrl, args.episodes, args.near, args.excess)
        team = f"{sc.spec.team.formation} {sc.spec.team.n}, {sc.spec.robot.drive}"
        print(f"| {sc.name} | {team} | {wall} | {wall_under} | {robots} | {robots_under} | {contacts} |", flush=True)


if __name__ == "__main__":
    main()
