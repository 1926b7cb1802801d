"""Faults injected by the world and its sensing, so that every method meets them the same way and none can ignore them
(`world.faults`, docs/faults.md).

Kinds, each active from `start` to `end` seconds (`end: null`: to the end of the episode):
- `stuck`: robot `robot`'s actuators ignore every command (it stops as fast as its acceleration allows and stays,
  unless pushed); Zhu et al. 2019, Section IV-D's actuator fault.
- `silent`: robot `robot` sends nothing: no other robot hears it (it still hears them); Zhu et al. 2019, Section
  IV-D's communication fault. A method that needs two-way links (Zhu's consensus) loses both directions.
- `drop`: every message between any two robots is lost with probability `prob` (independently per pair and step).
- `dropout`: robot `robot`'s sensors return nothing: it sees no robot and no obstacle.

Detection is the methods' business: no controller reads this list (Zhu's stuck and silence detection read only what
its robots observe).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FAULT_KINDS = ("stuck", "silent", "drop", "dropout")
ROBOT_FAULTS = ("stuck", "silent", "dropout")


@dataclass
class Fault:
    """One injected fault (section `world.faults`, a list)."""

    kind: str = "stuck"
    """stuck, silent, drop or dropout (module docstring)."""
    robot: int = 0
    """The robot it hits (stuck, silent, dropout)."""
    start: float = 0.0
    """When it begins (s)."""
    end: float | None = None
    """When it ends (s); null: it lasts to the end of the episode."""
    prob: float = 0.0
    """drop: the probability that a message is lost."""

    def active(self, t: float) -> bool:
        return self.start <= t + 1e-9 and (self.end is None or t + 1e-9 < self.end)

    def describe(self) -> str:
        what = f"robot {self.robot}" if self.kind in ROBOT_FAULTS else f"p={self.prob:g}"
        return f"{self.kind} {what} from {self.start:g} s" + (f" to {self.end:g} s" if self.end is not None else "")

    def check(self, key: str) -> None:
        from stafpipe.errors import require

        require(self.kind in FAULT_KINDS, f"{key}.kind", f"must be one of {list(FAULT_KINDS)}", self.kind)
        require(self.start >= 0, f"{key}.start", "must be >= 0", self.start)
        require(self.end is None or self.end > self.start, f"{key}.end", "must be after start (or null)", self.end)
        require(0 <= self.prob <= 1, f"{key}.prob", "must be in [0, 1]", self.prob)
        require(self.kind != "drop" or self.prob > 0, f"{key}.prob", "a drop fault needs prob > 0", self.prob)
        require(self.robot >= 0, f"{key}.robot", "must be a robot index >= 0", self.robot)


def robots_hit(faults: list[Fault], kind: str, t: float, n: int) -> np.ndarray:
    """(n,) bool: robots under an active fault of `kind` at time t."""
    hit = np.zeros(n, dtype=bool)
    for f in faults:
        if f.kind == kind and f.active(t):
            hit[f.robot] = True
    return hit


def drop_probability(faults: list[Fault], t: float) -> float:
    """The chance that a message is lost at time t (active drop faults combined as independent losses)."""
    keep = 1.0
    for f in faults:
        if f.kind == "drop" and f.active(t):
            keep *= 1.0 - f.prob
    return 1.0 - keep


def transitions(faults: list[Fault], before: float, after: float) -> list[tuple[str, Fault]]:
    """("fault", f) for faults that began and ("fault_end", f) for those that ended between two sample times."""
    out = []
    for f in faults:
        if not f.active(before) and f.active(after):
            out.append(("fault", f))
        elif f.active(before) and not f.active(after):
            out.append(("fault_end", f))
    return out
