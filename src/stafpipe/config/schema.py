"""Config dataclasses, one per config group or section, registered in Hydra's ConfigStore by `register_configs`.

Types are checked by Hydra when the config is composed (a wrong key or type fails before any work); value ranges are
checked by `check()` methods, which name the full key of a bad value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from omegaconf import MISSING

from stafpipe.errors import require
from stafpipe.formations import FORMATION_TYPES
from stafpipe.highlevel.config import AblateConfig, HighLevelConfig, TrainHighConfig
from stafpipe.learning.config import TrainPPOConfig
from stafpipe.mapgen import MapsConfig
from stafpipe.scenario import ScenarioConfig
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig


@dataclass
class FormationConfig:
    """The team's formation template (group `formation`)."""

    type: str | None = "circle"
    """One of circle, wedge, line, square, t, v; null (option `scenario`) keeps the scenario's own formation."""
    spacing: float | None = 1.0
    """Distance between neighbouring slots, in metres; null keeps the scenario's."""
    angle_deg: float = 90.0
    """Apex angle of the `v` formation in degrees (Cezayirli simulation 2 uses 120)."""

    def check(self, key: str = "formation", allow_unset: bool = False) -> None:
        if allow_unset and self.type is None:
            return
        require(self.type in FORMATION_TYPES, f"{key}.type", f"must be one of {list(FORMATION_TYPES)}", self.type)
        require(self.spacing is not None and self.spacing > 0, f"{key}.spacing", "must be > 0", self.spacing)
        require(0 < self.angle_deg < 180, f"{key}.angle_deg", "must be in (0, 180)", self.angle_deg)


@dataclass
class RobotConfig:
    """Overrides of the scenario's robot (group `robot`); a null field keeps the scenario file's value."""

    radius: float | None = None
    max_speed: float | None = None
    max_accel: float | None = None
    drive: str | None = None
    """holonomic (STAF's Gazebo robots) or diff_drive (Warthog, Limo; STAF Section 4)."""
    max_turn_rate: float | None = None

    def overrides(self) -> dict[str, Any]:
        """The fields that replace the scenario's."""
        return {k: v for k, v in self.__dict__.items() if v is not None}


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
class EvalConfig:
    """Evaluation settings (section `eval`)."""

    episodes: int = 10
    """Seeded episodes; episode k uses seed `seed * 100003 + k` for its start perturbation and sensing noise."""
    goal_tolerance: float = 0.3
    """A robot is at its goal within this distance (m)."""
    cfi_margin: float = 0.1
    """Safety margin (m) taken off each side of the narrowest passage for CFI's eta (STAF Section 4)."""
    log_episodes: bool = True
    """Write one MCAP file per episode under episodes/."""
    label: str = ""
    """Free text written into every results row (column `label`): tells variants of one method apart in
    `stafpipe plot table` (e.g. the `staf_levels` ablation)."""
    batch: int = 0
    """Episodes run at once, in parallel worlds of one batched world (a learned method's features and plans in one
    pass); 0: all of them, up to 50 and up to 5 M robot pairs (`stages.eval.auto_batch`: 5 worlds
    of 1,000 robots). An episode's result does not depend on this (a test)."""

    def check(self, key: str = "eval") -> None:
        require(self.episodes >= 1, f"{key}.episodes", "must be >= 1", self.episodes)
        require(self.batch >= 0, f"{key}.batch", "must be >= 0 (0: automatic)", self.batch)
        require(self.goal_tolerance > 0, f"{key}.goal_tolerance", "must be > 0", self.goal_tolerance)
        require(self.cfi_margin >= 0, f"{key}.cfi_margin", "must be >= 0", self.cfi_margin)


PLOT_KINDS = (
    "trajectories",
    "partitions",
    "training",
    "connectivity",
    "regions",
    "timing",
    "table",
    "report",
    "adaptation",
    "video",
)
FORMATS = ("png", "pdf", "svg")
VIDEO_FORMATS = ("mp4", "gif")


@dataclass
class PlotConfig:
    """Plot settings (section `plot`)."""

    kind: str = "trajectories"
    """What to draw: `trajectories` (an eval run: STAF Fig. 4 style, one figure per episode log) or `partitions` (an
    ablate run: its example partitions, and the ARI curve of the noise study), `training` (a train-ppo or train-high
    run: its learning curves), `connectivity` (an eval run: links and lambda2 over time, Cezayirli Fig. 4), `regions`
    (an eval run of method=zhu: snapshots of common regions, target formations and robots, Zhu Fig. 4) or `timing`
    (an eval run of method=zhu: the computation-time table, Zhu Table I, as timing.md and timing.tex) or `table` (eval
    runs, `run_dir` and/or `run_dirs`: STAF Table 1 and Table 2, ours beside the paper's, as table.md/.csv) or `report`
    (any finished eval, ablate and plot runs, `run_dirs`: every claim of the three papers with its computed verdict, as
    REPRODUCTION.md and reproduction.csv; `stafpipe run reproduce`) or `video` (an eval run's episode logs, or one
    episode's .mcap file: an MP4 and a GIF per episode)."""
    run_dir: str = ""
    """The run directory to draw from (`video`: or an episode's .mcap file)."""
    run_dirs: list[str] = field(default_factory=list)
    """`table`: more eval run directories whose episodes join the table; `report`: the runs it reads."""
    max_episodes: int = 4
    """Draw at most this many episodes, in episode order (0: all)."""
    times: list[float] = field(default_factory=list)
    """`regions`: the snapshot times (s); empty: the first split, the merge after it, and the end."""
    formats: list[str] = field(default_factory=lambda: ["png", "pdf"])
    dpi: int = 150
    video_formats: list[str] = field(default_factory=lambda: ["mp4", "gif"])
    """`video`: the files written per episode (mp4: H.264, gif: looping)."""
    fps: float = 10.0
    """`video`: frames per second; with `stride` 1 and the simulator's 0.1 s step, 10 plays the episode in real time."""
    stride: int = 1
    """`video`: one frame every `stride` logged steps (the last step always has one)."""
    width_px: int = 960
    """`video`: frame width in pixels (rounded down to a multiple of 16, as H.264 codes 16-pixel blocks)."""

    def check(self, key: str = "plot") -> None:
        require(self.kind in PLOT_KINDS, f"{key}.kind", f"must be one of {list(PLOT_KINDS)}", self.kind)
        require(
            bool(self.run_dir) or bool(self.run_dirs),
            f"{key}.run_dir",
            "is required: the run directory to draw from",
            self.run_dir,
        )
        require(self.max_episodes >= 0, f"{key}.max_episodes", "must be >= 0", self.max_episodes)
        for fmt in self.formats:
            require(fmt in FORMATS, f"{key}.formats", f"entries must be in {list(FORMATS)}", fmt)
        require(self.dpi > 0, f"{key}.dpi", "must be > 0", self.dpi)
        require(bool(self.video_formats), f"{key}.video_formats", "must name at least one format", self.video_formats)
        for fmt in self.video_formats:
            require(fmt in VIDEO_FORMATS, f"{key}.video_formats", f"entries must be in {list(VIDEO_FORMATS)}", fmt)
        require(math.isfinite(self.fps) and 0 < self.fps <= 120, f"{key}.fps", "must be in (0, 120]", self.fps)
        require(self.stride >= 1, f"{key}.stride", "must be >= 1", self.stride)
        require(64 <= self.width_px <= 3840, f"{key}.width_px", "must be in [64, 3840]", self.width_px)


@dataclass
class StafConfig:
    """The root config every stage composes; a stage reads the sections it needs."""

    stage: str = MISSING
    """The stage this config runs (set by the stage's primary config)."""
    seed: int = 0
    """Seed of every random draw of the run."""
    formation: FormationConfig = field(default_factory=FormationConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    data: DataConfig = field(default_factory=DataConfig)
    maps: MapsConfig = field(default_factory=MapsConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    method: Any = MISSING
    """The method (group `method`); each option has its own dataclass (stafpipe.registry.METHODS)."""
    world: WorldConfig = field(default_factory=WorldConfig)
    sensing: SensingConfig = field(default_factory=SensingConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    plot: PlotConfig = field(default_factory=PlotConfig)
    high: HighLevelConfig = field(default_factory=HighLevelConfig)
    train_high: TrainHighConfig = field(default_factory=TrainHighConfig)
    ablate: AblateConfig = field(default_factory=AblateConfig)
    train_ppo: TrainPPOConfig = field(default_factory=TrainPPOConfig)
