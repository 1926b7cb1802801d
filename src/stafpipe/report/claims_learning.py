"""Does learning carry STAF-planned? The `staf_levels` study's rows: the learned levels (b) against the strongest
non-learned variant on every map, judged outside the intervals (docs/reproduction.md)."""

from __future__ import annotations

import math

import pandas as pd

from stafpipe.plots.staf_tables import LABELS
from stafpipe.report.claims import PLANNED, Claim, Measured
from stafpipe.report.evidence import Evidence, column_number, lowest
from stafpipe.report.verdicts import HOLDS, Criterion, Number

OURS = LABELS[PLANNED]


NON_LEARNED = ("a", "d", "f")
"""staf_levels' variants without a network: (a) no learning, (d) the warm-start teacher, (f) no learning with the
approach cap; (b) is the learned method as shipped."""


def _levels(ev: Evidence) -> dict[str, dict[str, pd.DataFrame]]:
    """staf_levels' episodes by map (scenario and formation) and variant letter, for the maps that have (b) and at
    least one non-learned variant."""
    rows = ev.episodes
    if rows.empty or "label" not in rows:
        return {}
    variant = rows["label"].str.split("-").str[0]  # staf_levels labels its variants "a-no-learning", "b-...", ...
    keep = variant.isin(["b", *NON_LEARNED])
    rows = rows.assign(variant=variant)[(rows["method"] == PLANNED) & keep & (rows["faults"] == "")]
    out: dict[str, dict[str, pd.DataFrame]] = {}
    for (scenario, formation, label), g in rows.groupby(["scenario", "formation", "variant"]):
        out.setdefault(f"{scenario} {formation}", {})[str(label)] = g
    return {k: v for k, v in out.items() if "b" in v and set(v) & set(NON_LEARNED)}


METRICS = (("sr", True), ("collisions", False), ("cfi_0.5", True))
"""What "better" means between two variants on one map: success rate, collisions per episode, CFI(0.5)."""


def _better(x: pd.DataFrame, y: pd.DataFrame, column: str, higher: bool) -> bool:
    """x's mean of `column` above (`higher`) or below y's, outside both intervals."""
    if column not in x or column not in y:
        return False
    ours, theirs = column_number(x, column), column_number(y, column)
    return Criterion.than("above" if higher else "below", theirs).verdict(ours) == HOLDS


def _beats(x: pd.DataFrame, y: pd.DataFrame) -> bool:
    """x better than y outside both intervals in at least one of `METRICS` and worse in none."""
    return any(_better(x, y, c, h) for c, h in METRICS) and not any(_better(y, x, c, h) for c, h in METRICS)


def learning_claims() -> list[Claim]:
    def beats(ev: Evidence) -> Measured:
        maps = _levels(ev)
        hits = sum(all(_beats(v["b"], v[k]) for k in NON_LEARNED if k in v) for v in maps.values())
        return Measured(
            Number(hits if maps else math.nan, 0, len(maps)),
            Criterion("at_least", math.floor(len(maps) / 2) + 1 if maps else math.nan),
            f"maps of {len(maps)} where (b) beats every non-learned variant ({', '.join(NON_LEARNED)}) outside the "
            "CIs in SR, collisions or CFI(0.5) and is worse in none; holds on more than half of them",
        )

    def worse(ev: Evidence) -> Measured:
        maps = _levels(ev)
        hits = sum(any(_beats(v[k], v["b"]) for k in NON_LEARNED if k in v) for v in maps.values())
        return Measured(
            Number(hits if maps else math.nan, 0, len(maps)),
            Criterion("at_most", 0),
            f"maps of {len(maps)} where a non-learned variant ({', '.join(NON_LEARNED)}) beats (b) outside the CIs",
        )

    def generated(ev: Evidence) -> Measured:
        rows = ev.episodes
        if rows.empty:
            return Measured(Number(math.nan), Criterion("at_least", 95))
        rows = rows[
            (rows["method"] == PLANNED) & rows["label"].str.startswith("b-") & rows["scenario"].str.startswith("gen")
        ]
        srs = [column_number(g, "sr", 100, " %") for _, g in rows.groupby("scenario")]
        return Measured(lowest(srs), Criterion("at_least", 95), f"the lowest of {len(srs)} generated maps")

    return [
        Claim(
            "STAF",
            "Sec. 3 (ours: staf_levels)",
            "the learned levels (b) beat the strongest non-learned variant on maps they were not trained on",
            "the method's learned levels carry it",
            "staf_levels",
            beats,
        ),
        Claim(
            "STAF",
            "Sec. 3 (ours: staf_levels)",
            "no non-learned variant beats the learned levels (b) on any map",
            "-",
            "staf_levels",
            worse,
        ),
        Claim(
            "STAF",
            "Generalisation (ours)",
            f"{OURS} succeeds on generated maps it was not trained on (holonomic and differential drive)",
            "-",
            "staf_levels",
            generated,
        ),
    ]
