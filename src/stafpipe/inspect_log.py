"""`stafpipe inspect FILE.mcap`: what an episode log holds, and its metrics recomputed from the log alone."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from stafpipe.episode import scenario_from_yaml, trajectory_from_record
from stafpipe.episode_log import EpisodeRecord, LogError, outline_episode, read_episode, require_log_file
from stafpipe.mcap_check import FileView, check
from stafpipe.metrics import MetricContext, episode_metrics


def recompute_metrics(rec: EpisodeRecord) -> dict[str, float]:
    """The episode's metrics from its log: trajectory, scenario map and metric context all come from the file."""
    scenario = scenario_from_yaml(rec.scenario_yaml)
    return episode_metrics(trajectory_from_record(rec, scenario), MetricContext(**rec.context))


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9)


MAX_RECOMPUTED = 200_000
"""Robot-steps (steps x robots) of the largest log whose metrics `inspect` recomputes: the whole trajectory and the
metrics' work arrays are held in memory for that (about 1 kB a robot-step, measured). A longer log is checked and
outlined message by message, and the report says its metrics were not recomputed (benchmarks/inspect_memory.py)."""


def describe(path: str) -> tuple[str, bool]:
    """A human-readable report of the log; True when the recomputed metrics equal the logged ones (or were not
    compared, as the report says). A damaged file (any CRC, magic or record length that does not hold:
    mcap_check.check) is an error naming the first damage. Memory stays bounded for a log of any size."""
    file = Path(path)
    require_log_file(file)
    with open(file, "rb") as f:
        damage = check(FileView(f))
    if damage:
        more = f" and {len(damage) - 1} more" if len(damage) > 1 else ""
        raise LogError(f"{path}: damaged at {damage[0]}{more}; `stafpipe inspect --recover` keeps every intact chunk")
    out = outline_episode(path)
    lines = [
        f"{path}",
        f"  method {out.method}, seed {out.seed}, {out.robots} robots, {out.steps} steps, {out.duration:.1f} s",
        "  channels: " + ", ".join(f"{t} ({n})" for t, n in sorted(out.topics.items())),
        "  subteams over time:",
    ]
    for time, labels in out.changes:
        groups = {int(s): [int(i) for i in np.flatnonzero(labels == s)] for s in np.unique(labels)}
        lines.append(f"    t={time:7.1f} s  " + "  ".join(f"{s}: {g}" for s, g in groups.items()))
    lines.append("  events: " + (", ".join(f"{k} x{n}" for k, n in sorted(out.events.items())) or "none"))
    if out.recovered is not None:
        lines.insert(1, f"  PARTIAL episode, recovered from a damaged log ({out.recovered})")
    if out.steps * out.robots > MAX_RECOMPUTED:
        lines.append(
            f"  metrics NOT recomputed: {out.steps * out.robots:,} robot-steps is more than inspect holds in memory "
            f"({MAX_RECOMPUTED:,}); the log is intact (every CRC holds)"
        )
        return "\n".join(lines), True
    rec = read_episode(path)
    recomputed = recompute_metrics(rec)
    logged = rec.metrics if rec.metrics and rec.recovered is None else {}  # a partial episode has other metrics
    # a metric added after the log was written is shown, not compared (the log cannot disagree with it)
    equal = all(_same(recomputed[k], float(logged[k])) for k in recomputed if k in logged) if logged else True
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
