"""Decision time of STAF's high level (shipped checkpoint): graph, network, hard assignment and repair, one team.

Usage: python benchmarks/high_level_latency.py [--repeats 50]
Targets (issue 5): 10 robots well under 1 ms; 1,000 robots (sparse radius graph) under 50 ms. One torch thread, as a
robot's onboard computer would run it; the table also shows where the time goes. Teams up to SMALL_TEAM robots run the
numpy forward pass (built once, as a controller holds it), larger ones the torch edge-list network.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from stafpipe.formations import formation_slots, place
from stafpipe.highlevel.checkpoint import load_checkpoint
from stafpipe.highlevel.graphs import Team, collate, team_graph
from stafpipe.highlevel.infer import SMALL_TEAM
from stafpipe.highlevel.model import NumpyGraphCut
from stafpipe.highlevel.partition import hard_assignment


def timed(fn, repeats: int) -> tuple[float, object]:
    out, times = None, []
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    torch.set_num_threads(1)
    model, _ = load_checkpoint()
    cfg = model.cfg
    fast = NumpyGraphCut(model)
    print(
        f"{'robots':>7} | {'formation':>9} | {'m':>2} | {'edges':>6} | {'graph ms':>8} | {'network ms':>10} | "
        f"{'assign+repair ms':>16} | {'total ms':>8}"
    )
    print("-" * 92)
    for n, kind, m in ((10, "circle", 2), (100, "square", 3), (1000, "square", 4)):
        slots = formation_slots(kind, n, 1.0)
        team = Team(place(slots, (0.0, 0.0), 0.0), place(slots, (30.0, 0.0), 0.0), m)
        repeats = args.repeats if n < 1000 else max(5, args.repeats // 5)
        t_graph, graph = timed(lambda: team_graph(team, cfg.features, cfg.radius), repeats)
        if n <= SMALL_TEAM:  # what stafpipe.highlevel.infer.predict does for one small team
            t_net, y = timed(lambda: fast(graph.x, graph.edges, m), repeats)
        else:
            batch = collate([graph], [m])
            with torch.no_grad():
                t_net, y = timed(lambda: model(batch).numpy(), repeats)
        t_assign, _ = timed(lambda: hard_assignment(y, graph.edges, m), repeats)
        total = t_graph + t_net + t_assign
        print(
            f"{n:>7} | {kind:>9} | {m:>2} | {graph.edges.shape[1]:>6} | {t_graph:>8.3f} | {t_net:>10.3f} | "
            f"{t_assign:>16.3f} | {total:>8.3f}"
        )


if __name__ == "__main__":
    main()
