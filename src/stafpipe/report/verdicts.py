"""Numbers and the criteria that turn them into verdicts. A verdict is computed, never typed: `Criterion.verdict`."""

from __future__ import annotations

import math
from dataclasses import dataclass

HOLDS, PARTLY, FAILS, MISSING = "holds", "partly", "does not hold", "not measured"


@dataclass(frozen=True)
class Number:
    """A measured value with its 95 % confidence half-width (0 when exact, NaN when unknown) and sample size."""

    value: float
    ci: float = 0.0
    n: int = 0
    unit: str = ""

    @property
    def half(self) -> float:
        """The half-width used by the criteria (an unknown CI counts as 0)."""
        return 0.0 if math.isnan(self.ci) else self.ci

    def text(self, digits: int = 1) -> str:
        if math.isnan(self.value):
            return "-"
        ci = "" if self.half == 0 else f" ± {self.half:.{digits}f}"
        n = f" (n={self.n})" if self.n else ""
        return f"{self.value:.{digits}f}{ci}{self.unit}{n}"


@dataclass(frozen=True)
class Criterion:
    """How a number is judged.

    at_least  holds if value + CI >= target; partly if value + CI >= target - slack
    at_most   holds if value - CI <= target; partly if value - CI <= target + slack
    near      holds if |value - target| <= slack + CI; partly if <= 2 slack + CI
    above     holds if value - CI > target + its CI (outside both CIs); partly if value > target; `target_ci` is the
              other number's CI
    below     holds if value + CI < target - its CI; partly if value < target
    """

    kind: str
    target: float
    slack: float = 0.0
    target_ci: float = 0.0
    min_effect: float = 0.0
    """above/below: the least difference that counts at all (a difference of a few thousandths outside tight CIs is
    not a finding)."""

    def __post_init__(self) -> None:
        if self.kind not in ("at_least", "at_most", "near", "above", "below"):
            raise ValueError(f"criterion kind {self.kind!r}: must be at_least, at_most, near, above or below")

    def verdict(self, ours: Number) -> str:
        if math.isnan(ours.value) or math.isnan(self.target):
            return MISSING
        v, h, t, s = ours.value, ours.half, self.target, self.slack
        if self.kind == "at_least":
            return HOLDS if v + h >= t else PARTLY if v + h >= t - s else FAILS
        if self.kind == "at_most":
            return HOLDS if v - h <= t else PARTLY if v - h <= t + s else FAILS
        if self.kind == "near":
            d = abs(v - t)
            return HOLDS if d <= s + h else PARTLY if d <= 2 * s + h else FAILS
        other = 0.0 if math.isnan(self.target_ci) else self.target_ci
        if self.kind == "below":
            v, t = -v, -t  # below t is above -t
        if v - t < self.min_effect:
            return FAILS
        return HOLDS if v - h > t + other else PARTLY

    def text(self, digits: int = 1) -> str:
        t, s = f"{self.target:.{digits}f}", f"{self.slack:.{digits}f}"
        if self.kind == "at_least":
            return f"holds if ours (+ CI) >= {t}; partly if >= {self.target - self.slack:.{digits}f}"
        if self.kind == "at_most":
            return f"holds if ours (- CI) <= {t}; partly if <= {self.target + self.slack:.{digits}f}"
        if self.kind == "near":
            return f"holds if within {s} (+ CI) of {t}; partly if within {2 * self.slack:.{digits}f}"
        effect = f" by at least {self.min_effect:g}" if self.min_effect else ""
        if self.kind == "below":
            return f"holds if ours is below {t}{effect} outside both CIs; partly if below{effect} within them"
        return f"holds if ours exceeds {t}{effect} outside both CIs; partly if above{effect} within them"
