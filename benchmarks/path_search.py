"""Bounded shortest-path searches (`geometry.SEARCH_BOUNDS`) against searches of the whole grid: on every built-in
scenario and on generated maps, each leg of the team's route at the robot's radius and at 0.5 m, the path traced
cell for cell from both searches, and the time of each.

Usage: python benchmarks/path_search.py [--maps 40] [--seed 4711]
Prints one row per kind of map: legs searched, legs whose traced cells differ (must be 0), the whole-grid and the
bounded searches' seconds, and their ratio.
"""

from __future__ import annotations

import argparse
import itertools
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra

from stafpipe.episode import _route
from stafpipe.geometry import Geometry
from stafpipe.paths import conf_dir
from stafpipe.scenario import Scenario, build_scenario, load_scenario_file
from stafpipe.scenario_pool import load_named_scenario


def compare(scenarios: list[Scenario]) -> tuple[int, int, float, float]:
    """(legs, legs that differ, whole-grid seconds, bounded seconds) over the scenarios' route legs."""
    legs = differ = 0
    whole = bounded = 0.0
    for sc in scenarios:
        geo = Geometry(sc)
        for clearance in (sc.spec.robot.radius, 0.5):
            graph = geo._graph(clearance)
            for a, b in itertools.pairwise(_route(sc)):
                s, g = geo._node(a), geo._node(b)
                start = time.perf_counter()
                dist, pred = dijkstra(graph, directed=False, indices=s, return_predecessors=True)
                whole += time.perf_counter() - start
                if not np.isfinite(dist[g]):
                    continue  # no way at this clearance: both searches end on the whole grid
                start = time.perf_counter()
                near, near_pred, _ = geo._search(clearance, s, g, math.dist(a, b))
                bounded += time.perf_counter() - start
                legs += 1
                asked = (a, b, clearance)
                one, two = geo._trace(dist, pred, g, s, asked), geo._trace(near, near_pred, g, s, asked)
                differ += int(len(one) != len(two) or not (one == two).all() or dist[g] != near[g])
    return legs, differ, whole, bounded


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--maps", type=int, default=40)
    parser.add_argument("--seed", type=int, default=4711, help="the generated maps' generate-maps seed")
    args = parser.parse_args()
    built_in = sorted(p.stem for p in (conf_dir() / "scenario").glob("*.yaml"))
    kinds = {"built-in": [load_named_scenario(name) for name in built_in]}
    with tempfile.TemporaryDirectory() as tmp:
        words = ["generate-maps", f"seed={args.seed}", f"maps.count={args.maps}", f"hydra.run.dir={tmp}/gen"]
        subprocess.run([sys.executable, "-m", "stafpipe", *words], check=True, capture_output=True)
        files = sorted((Path(tmp) / "gen" / "maps").glob("*.yaml"))
        kinds[f"generated (seed {args.seed})"] = [build_scenario(load_scenario_file(f)) for f in files]
    print("| maps | scenarios | legs | legs that differ | whole grid (s) | bounded (s) | ratio |")
    print("|---|---|---|---|---|---|---|")
    for kind, scenarios in kinds.items():
        legs, differ, whole, bounded = compare(scenarios)
        ratio = whole / bounded
        print(f"| {kind} | {len(scenarios)} | {legs} | {differ} | {whole:.1f} | {bounded:.1f} | {ratio:.2f} |")


if __name__ == "__main__":
    main()
