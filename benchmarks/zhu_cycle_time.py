"""Zhu et al. 2019, Table I: computation time per cycle of each part of `method=zhu`, for 4, 16 and 100 robots.

Usage: python benchmarks/zhu_cycle_time.py [--seconds 30] [--sizes 4 16 100]
Target (issue 4): <= 2.4 ms mean total per cycle for 4 robots (the paper: 238.6 ms in MATLAB). Times are for the
whole team in one process (every robot's region, every pair of the intersection graph), so they are an upper bound
on one robot's share. 4 robots: Scenario 1 (the moving obstacle); 16: Scenario 2 (obstacle and corridor); 100: a
10 x 10 square crossing a field of pillars. "Total" is the sum of the part means, as in the paper.
"""

from __future__ import annotations

import argparse
import dataclasses

import pandas as pd

from stafpipe.controllers.zhu import ZhuController
from stafpipe.controllers.zhu_config import ZhuConfig
from stafpipe.episode import run_episode
from stafpipe.geometry import Geometry
from stafpipe.io import markdown_table
from stafpipe.paths import conf_dir
from stafpipe.plots.zhu import timing_table
from stafpipe.scenario import ScenarioConfig, TeamSpec, WorldBounds, build_scenario, load_scenario_file
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig


def _pillars() -> ScenarioConfig:
    pillars = [{"circle": {"center": [float(x), float(y)], "radius": 0.6}} for x in (25, 35, 45) for y in (-8, 0, 8)]
    return ScenarioConfig(
        name="zhu_pillars100",
        world=WorldBounds(0, -20, 70, 20),
        obstacles=pillars,
        team=TeamSpec(n=100, formation="square", spacing=1.0, start=(8.0, 0.0), goal=(60.0, 0.0), heading_deg=0.0),
        time_limit=120.0,
    )


def scenario_for(n: int) -> ScenarioConfig:
    if n == 4:
        return load_scenario_file(conf_dir() / "scenario" / "zhu_moving_obstacle.yaml")
    if n == 16:
        return load_scenario_file(conf_dir() / "scenario" / "zhu_corridor16.yaml")
    if n == 100:
        return _pillars()
    raise SystemExit(f"no benchmark scenario for {n} robots (sizes: 4, 16, 100)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=30.0, help="simulated seconds per team size")
    parser.add_argument("--sizes", type=int, nargs="+", default=[4, 16, 100])
    parser.add_argument("--episodes", type=int, default=3, help="seeded episodes per team size")
    args = parser.parse_args()
    summary = []
    for n in args.sizes:
        spec = dataclasses.replace(scenario_for(n), time_limit=args.seconds)
        scenario = build_scenario(spec)
        geometry = Geometry(scenario, resolution=0.1)
        rows, most = [], 0
        for seed in range(args.episodes):
            controller = ZhuController(ZhuConfig())
            values = run_episode(scenario, geometry, controller, "zhu", seed, WorldConfig(), SensingConfig(radius=3.0))
            rows.append(controller.world_view(0).episode_stats())
            most = max(most, int(values["subteams_max"]))
        table = timing_table(pd.DataFrame(rows))
        print(
            f"\n{n} robots, {spec.name}, {args.episodes} episodes of {args.seconds:g} s simulated "
            f"(at most {most} subteams)"
        )
        print(markdown_table(table.astype(object).where(table.notna(), "--"), digits=3))
        total = float(table["Mean."].iloc[-1])
        cycle = float(table.set_index("Computations").loc[["Convex regions", "Local formation control"], "Mean."].sum())
        summary.append(
            {
                "robots": n,
                "total (sum of means) ms": total,
                "mean 5 Hz cycle ms": cycle,
                "target": "<= 2.4 ms" if n == 4 else "report",
            }
        )
    print("\nsummary\n" + markdown_table(pd.DataFrame(summary), digits=3))


if __name__ == "__main__":
    main()
