"""Config dataclasses, one per config group or section, registered in Hydra's ConfigStore by `register_configs`.

Types are checked by Hydra when the config is composed (a wrong key or type fails before any work); value ranges are
checked by `check()` methods, which name the full key of a bad value.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from omegaconf import MISSING

from stafpipe.errors import ConfigError
from stafpipe.formations import FORMATION_TYPES


def require(ok: bool, key: str, message: str, value: Any) -> None:
    """Raise a ConfigError naming `key` unless `ok`."""
    if not ok:
        raise ConfigError(f"{key} {message}, got {value!r}")


@dataclass
class FormationConfig:
    """The team's formation template (group `formation`)."""

    type: str = "circle"
    """One of circle, wedge, line, square, t, v."""
    spacing: float = 1.0
    """Distance between neighbouring slots, in metres."""
    angle_deg: float = 90.0
    """Apex angle of the `v` formation in degrees (Cezayirli simulation 2 uses 120)."""

    def check(self, key: str = "formation") -> None:
        require(self.type in FORMATION_TYPES, f"{key}.type", f"must be one of {list(FORMATION_TYPES)}", self.type)
        require(self.spacing > 0, f"{key}.spacing", "must be > 0", self.spacing)
        require(0 < self.angle_deg < 180, f"{key}.angle_deg", "must be in (0, 180)", self.angle_deg)


@dataclass
class DataConfig:
    """The synthetic formation dataset of `stafpipe generate` (STAF Appendix C: 10,000 instances)."""

    instances: int = 10_000
    """Number of team instances (STAF Appendix C: 10,000)."""
    n_min: int = 4
    """Smallest team size drawn (inclusive)."""
    n_max: int = 12
    """Largest team size drawn (inclusive)."""
    mix: list[str] = field(default_factory=list)
    """Formation types to draw from uniformly; empty means only `formation.type`."""
    spacing_jitter: float = 0.2
    """Spacing is `formation.spacing` times U(1 - jitter, 1 + jitter)."""
    heading_range_deg: float = 180.0
    """Heading drawn from U(-range, range) degrees."""
    translation: float = 10.0
    """Formation centre drawn from U(-translation, translation) on each axis, in metres."""
    position_noise: float = 0.1
    """Standard deviation of the Gaussian noise added to each robot's slot position, in metres."""
    goal_distance: list[float] = field(default_factory=lambda: [10.0, 30.0])
    """Range of the distance from the start centre to the goal centre, in metres."""
    goal_heading_jitter_deg: float = 30.0
    """The goal lies ahead along the heading, turned by U(-jitter, jitter) degrees."""
    corridor_width: list[float] = field(default_factory=lambda: [0.6, 4.0])
    """Range of the width of the narrowest passage ahead of the team, in metres."""

    def check(self, key: str = "data") -> None:
        require(self.instances >= 1, f"{key}.instances", "must be >= 1", self.instances)
        require(self.n_min >= 2, f"{key}.n_min", "must be >= 2", self.n_min)
        require(self.n_max >= self.n_min, f"{key}.n_max", f"must be >= data.n_min ({self.n_min})", self.n_max)
        for kind in self.mix:
            require(kind in FORMATION_TYPES, f"{key}.mix", f"entries must be in {list(FORMATION_TYPES)}", kind)
        require(0 <= self.spacing_jitter < 1, f"{key}.spacing_jitter", "must be in [0, 1)", self.spacing_jitter)
        require(self.translation >= 0, f"{key}.translation", "must be >= 0", self.translation)
        require(self.position_noise >= 0, f"{key}.position_noise", "must be >= 0", self.position_noise)
        for name in ("goal_distance", "corridor_width"):
            lo_hi = list(getattr(self, name))
            ok = len(lo_hi) == 2 and 0 <= lo_hi[0] <= lo_hi[1]
            require(ok, f"{key}.{name}", "must be [low, high] with 0 <= low <= high", lo_hi)


@dataclass
class StafConfig:
    """The root config every stage composes; a stage reads the sections it needs."""

    stage: str = MISSING
    """The stage this config runs (set by the stage's primary config)."""
    seed: int = 0
    """Seed of every random draw of the run."""
    formation: FormationConfig = field(default_factory=FormationConfig)
    data: DataConfig = field(default_factory=DataConfig)
