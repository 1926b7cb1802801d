"""A claim of a paper, the measurement that answers it, and the row it becomes in the report."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from stafpipe.report.evidence import Evidence, wilson
from stafpipe.report.verdicts import Criterion, Number

PLANNED = "staf_planned"
"""STAF-planned (ours): its rows stand beside the paper's STAF numbers as our own variant."""


@dataclass(frozen=True)
class Measured:
    """What a claim's measurement returns: our number, the criterion it is judged by, and a note (how it was read)."""

    ours: Number
    criterion: Criterion
    note: str = ""


@dataclass(frozen=True)
class Claim:
    paper: str
    artifact: str
    statement: str
    printed: str
    """The paper's number or words."""
    pipeline: str
    """The pipeline whose runs measure it."""
    measure: Callable[[Evidence], Measured]


@dataclass(frozen=True)
class Row:
    claim: Claim
    measured: Measured
    verdict: str


def judge(claim: Claim, evidence: Evidence) -> Row:
    """The claim's row: its measurement and the verdict its criterion computes (not measured without its runs)."""
    measured = claim.measure(evidence)
    return Row(claim, measured, measured.criterion.verdict(measured.ours))


def fraction(hits: int, total: int) -> Number:
    """hits out of total, in per cent, with Wilson's 95 % interval (NaN when nothing was measured)."""
    if not total:
        return Number(math.nan)
    low, high = wilson(hits / total, total)
    return Number(100.0 * hits / total, math.nan, total, " %", 100 * low, 100 * high)
