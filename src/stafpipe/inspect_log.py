"""`stafpipe inspect FILE.mcap`: what an episode log holds, and its metrics recomputed from the log alone."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from stafpipe.episode import scenario_from_yaml, trajectory_from_record
from stafpipe.episode_log import EpisodeRecord, LogError, read_episode
from stafpipe.mcap_check import check
from stafpipe.metrics import MetricContext, episode_metrics


def recompute_metrics(rec: EpisodeRecord) -> dict[str, float]:
    """The episode's metrics from its log: trajectory, scenario map and metric context all come from the file."""
    scenario = scenario_from_yaml(rec.scenario_yaml)
    return episode_metrics(trajectory_from_record(rec, scenario), MetricContext(**rec.context))


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)


def describe(path: str) -> tuple[str, bool]:
    """A human-readable report of the log; True when the recomputed metrics equal the logged ones. A damaged file
    (any CRC, magic or record length that does not hold: mcap_check.check) is an error naming the first damage."""
    file = Path(path)
    if not file.is_file():
        raise LogError(f"{path}: " + ("a directory, not an episode log" if Path(path).is_dir() else "no such file"))
    damage = check(file.read_bytes())
    if damage:
        more = f" and {len(damage) - 1} more" if len(damage) > 1 else ""
        raise LogError(f"{path}: damaged at {damage[0]}{more}; `stafpipe inspect --recover` keeps every intact chunk")
    rec = read_episode(path)
    recomputed = recompute_metrics(rec)
    lines = [
        f"{path}",
        f"  method {rec.method}, seed {rec.seed}, {rec.positions.shape[1]} robots, "
        f"{len(rec.time)} steps, {rec.time[-1]:.1f} s",
    ]
    lines.append("  channels: " + ", ".join(f"{t} ({n})" for t, n in sorted(rec.topics.items())))
    changes = [0] + [k for k in range(1, len(rec.time)) if not np.array_equal(rec.subteams[k], rec.subteams[k - 1])]
    lines.append("  subteams over time:")
    for k in changes[:20]:
        groups = {int(s): [int(i) for i in np.flatnonzero(rec.subteams[k] == s)] for s in np.unique(rec.subteams[k])}
        lines.append(f"    t={rec.time[k]:7.1f} s  " + "  ".join(f"{s}: {g}" for s, g in groups.items()))
    kinds: dict[str, int] = {}
    for e in rec.events:
        kinds[e["kind"]] = kinds.get(e["kind"], 0) + 1
    lines.append("  events: " + (", ".join(f"{k} x{n}" for k, n in sorted(kinds.items())) or "none"))
    logged = rec.metrics if rec.metrics and rec.recovered is None else {}  # a partial episode has other metrics
    # a metric added after the log was written is shown, not compared (the log cannot disagree with it)
    equal = all(_same(recomputed[k], float(logged[k])) for k in recomputed if k in logged) if logged else True
    if rec.recovered is not None:
        lines.insert(1, f"  PARTIAL episode, recovered from a damaged log ({rec.recovered})")
    verdict = (
        "not compared with the logged ones"
        if rec.recovered is not None
        else "no logged metrics to compare"
        if not logged
        else "equal to the logged ones"
        if equal
        else "DIFFERENT from the logged ones"
    )
    partial = "of the recovered part only, " if rec.recovered is not None else ""
    lines.append(f"  metrics ({partial}recomputed from the log; {verdict}):")
    for name, v in recomputed.items():
        if logged and name not in logged:
            mark = "   (not in the log: a newer metric)"
        else:
            mark = "" if not logged or _same(v, float(logged[name])) else f"   (logged {logged.get(name)})"
        lines.append(f"    {name:22s} {v:12.4f}{mark}")
    return "\n".join(lines), equal
