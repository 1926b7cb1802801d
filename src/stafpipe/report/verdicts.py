"""Numbers and the criteria that turn them into verdicts. A verdict is computed, never typed: `Criterion.verdict`.

Every criterion leans against the claim: "holds" needs the whole 95 % interval on the claim's side, so a wider interval
(fewer episodes, more spread) can only make a verdict weaker, never stronger; a number without an interval it could
have (one sample) never holds; a tie never holds. Thresholds are compared with the tolerance `TOLERANCE`, so that
floating-point rounding (|40 - 70| computed as 30.000000000000014) decides nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

HOLDS, PARTLY, FAILS, MISSING = "holds", "partly", "does not hold", "not measured"
ORDER = {MISSING: -1, FAILS: 0, PARTLY: 1, HOLDS: 2}
"""Verdicts from weakest to strongest (`tests/test_report.py` checks that a wider interval never climbs this order)."""
TOLERANCE = 1e-6
"""Absolute tolerance (in the number's own unit) within which a value counts as equal to a threshold."""


@dataclass(frozen=True)
class Number:
    """A measured value with its 95 % interval and sample size. The interval is `value` ± `ci` (0: exact; NaN:
    unknown, as for a single sample) unless `low` and `high` give it explicitly (a Wilson interval is not symmetric)."""

    value: float
    ci: float = 0.0
    n: int = 0
    unit: str = ""
    low: float = math.nan
    high: float = math.nan

    @property
    def lower(self) -> float:
        """The interval's lower end (-inf where the interval is unknown)."""
        if not math.isnan(self.low):
            return self.low
        return -math.inf if math.isnan(self.ci) else self.value - self.ci

    @property
    def upper(self) -> float:
        """The interval's upper end (+inf where the interval is unknown)."""
        if not math.isnan(self.high):
            return self.high
        return math.inf if math.isnan(self.ci) else self.value + self.ci

    def text(self, digits: int = 1) -> str:
        if math.isnan(self.value):
            return "-"
        if not math.isnan(self.low):
            ci = f" [{self.low:.{digits}f}, {self.high:.{digits}f}]" if self.high > self.low else ""
        elif math.isnan(self.ci):
            ci = " (no interval)" if self.n == 1 else ""
        else:
            ci = f" ± {self.ci:.{digits}f}" if self.ci else ""
        n = f" (n={self.n})" if self.n else ""
        return f"{self.value:.{digits}f}{ci}{self.unit}{n}"


@dataclass(frozen=True)
class Criterion:
    """How a number is judged (lo, hi: the ends of its 95 % interval; tol: `TOLERANCE`).

    at_least  holds if lo >= target; partly if only the value is (the interval reaches below); else does not hold
    at_most   holds if hi <= target; partly if only the value is; else does not hold
    near      holds if the whole interval lies within `slack` of target; partly if the value does; else does not hold
    above     holds if lo is above the other number's upper end (outside both intervals) and the difference is at
              least `min_effect`; partly if only the values are ordered so; a tie (or less) does not hold
    below     the mirror of above

    above and below are made with `Criterion.than(kind, other)`.
    """

    kind: str
    target: float
    slack: float = 0.0
    """near: the band either side of the target."""
    min_effect: float = 0.0
    """above/below: the least difference that counts at all (a difference of a few thousandths outside tight CIs is
    not a finding)."""
    other_low: float = math.nan
    other_high: float = math.nan
    """above/below: the other number's interval (`than`; +-inf where it is unknown, so the comparison cannot hold);
    left NaN, the target is an exact threshold."""

    def __post_init__(self) -> None:
        if self.kind not in ("at_least", "at_most", "near", "above", "below"):
            raise ValueError(f"criterion kind {self.kind!r}: must be at_least, at_most, near, above or below")
        if math.isnan(self.other_low):
            object.__setattr__(self, "other_low", self.target)
        if math.isnan(self.other_high):
            object.__setattr__(self, "other_high", self.target)

    @classmethod
    def than(cls, kind: str, other: Number, min_effect: float = 0.0) -> Criterion:
        """`above` or `below` the measured number `other`, outside both intervals."""
        return cls(kind, other.value, min_effect=min_effect, other_low=other.lower, other_high=other.upper)

    def verdict(self, ours: Number) -> str:
        if math.isnan(ours.value) or math.isnan(self.target):
            return MISSING
        v, lo, hi, t, tol = ours.value, ours.lower, ours.upper, self.target, TOLERANCE
        if self.kind == "at_least":
            return HOLDS if lo >= t - tol else PARTLY if v >= t - tol else FAILS
        if self.kind == "at_most":
            return HOLDS if hi <= t + tol else PARTLY if v <= t + tol else FAILS
        if self.kind == "near":
            inside = max(abs(lo - t), abs(hi - t)) <= self.slack + tol
            return HOLDS if inside else PARTLY if abs(v - t) <= self.slack + tol else FAILS
        o_lo, o_hi = self.other_low, self.other_high
        if self.kind == "below":  # below t is above -t
            v, lo, t, o_hi = -v, -hi, -t, -o_lo
        if v - t <= max(self.min_effect, tol):
            return FAILS
        return HOLDS if lo > o_hi + tol else PARTLY

    def text(self, digits: int = 1) -> str:
        t = f"{self.target:.{digits}f}"
        if self.kind == "at_least":
            return f"holds if the whole 95 % interval is >= {t}; partly if only the value is"
        if self.kind == "at_most":
            return f"holds if the whole 95 % interval is <= {t}; partly if only the value is"
        if self.kind == "near":
            s = f"{self.slack:.{digits}f}"
            return f"holds if the whole 95 % interval is within {s} of {t}; partly if the value is"
        effect = f" by more than {self.min_effect:g}" if self.min_effect else ""
        word = "below" if self.kind == "below" else "above"
        within = f"partly if {word}{effect} within them; a tie does not hold"
        return f"holds if {word} {t}{effect} outside both 95 % intervals; {within}"
