"""Settings of `method=zhu` (Zhu, Juhl, Ferranti and Alonso-Mora, ICRA 2019), checked before any work; the
controller is controllers/zhu.py."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from stafpipe.controllers.orca import ORCA_HORIZON, ORCA_MARGIN, ORCA_RECOVERY
from stafpipe.errors import require


@dataclass
class ZhuConfig:
    """Config of `method=zhu` (group `method`). Defaults: Scenario 1 of Section V-A where the paper gives values."""

    name: str = "zhu"
    visibility: float = 6.0
    """r_B, the visibility radius (Section V-A: 6 m). The communication range r_C is sensing.radius (3 m)."""
    visibility_sides: int = 8
    """The visibility disc is the regular polygon of this many sides inscribed in it (8: 90 % of the disc's area;
    fewer sides keep every polygon small, which is what Table I's timings pay for)."""
    behind: float = 1.0
    """Ours: a region reaches at most this far (m) behind its robot, seen from p_r, so that it lies where the team is
    going (Section II: P_i "is likely to make progress"); .inf keeps the whole visibility disc, and so does every
    region once p_r has reached the goal."""
    horizon: float = 3.0
    """tau, the time horizon of the position-time obstacles (1) (Section V-A: 3 s)."""
    decision_period: float = 1.0
    """ff: teams check splitting and merging every ff seconds (Section V-A: 1 s)."""
    control_period: float = 0.2
    """Regions and target formations are recomputed at the local planner's 5 Hz (Section V-A)."""
    v_min: float | None = None
    """V_min (Section IV-B), m^2; null: the footprint of the team's template (hull dilated by the robot radius)."""
    p_max: float = 3.0
    """Largest centre distance for a merge (Section IV-C); no value printed."""
    max_subteams: int = 4
    """Most parts one split may make (Section III: "one splitting action can lead to multiple sub-formations")."""
    reference_speed: float = 1.0
    """Speed of the global reference p_r along the team's path (m/s); it waits while every team lags by > max_lag."""
    max_lag: float = 2.5
    """Distance (m) between p_r and the nearest team centre beyond which p_r waits (waiting for the farthest team
    deadlocks when a subteam ahead blocks the one behind)."""
    team_reference: bool = True
    """Ours: a team more than max_lag from p_r whose straight way to p_r crosses an obstacle (for `team_wait`) aims
    at the path's point `team_lookahead` ahead of its own place on the path (never beyond p_r), for its region's
    "ahead" and its formation's fit; false: every team aims at p_r. With one p_r, a team left
    behind a wall while another went on through the door aimed at the wall's face nearest p_r for ever (docs/zhu.md,
    "Teams left behind")."""
    team_lookahead: float = 1.0
    """With team_reference: how far ahead (m) of a lagging team's place on the path it aims."""
    team_wait: float = 0.0
    """With team_reference: how long (s) a team stays over max_lag from p_r and out of its sight before it aims along
    the path; 0: at once. 3 s (as stall_time) was tried: better on an obstacle field where passing an obstacle hides p_r
    for a moment, worse on 41 generated maps (docs/zhu.md, "Teams left behind")."""
    scales: list[float] = field(default_factory=lambda: [1.0, 0.8])
    """Formation scales tried when fitting ([20] optimises the scale); a scale never takes the spacing below 2 r +
    0.1 m, and a team spaced tighter than that keeps its own spacing."""
    shape_penalty: float = 1.0
    """Cost (m) of each step down the list of shapes (preferred first, then narrower grids); the scale costs
    shape_penalty x (1 - scale)."""
    switch_penalty: float = 0.5
    """Ours: extra cost (m) of a shape or scale other than the team's last one, so that a team does not flicker
    between two near-equal formations (each change reshuffles the slots)."""
    gain: float = 1.5
    """Proportional gain (1/s) towards the slot; the speed is capped at the robot's preferred (max) speed."""
    avoid_distance: float = 0.35  # local_planner=cap (base.limit_approach): gap (m) under which approach is capped
    avoid_gain: float = 2.0  # local_planner=cap: approach speed (m/s) allowed per metre of gap beyond stop_gap
    stop_gap: float = 0.1
    """The gap (m) at which the approach stops (L&F uses 0.02; at 1.5 m/s and 3 m/s^2 a team that reshuffles its
    slots needs the larger margin: Scenario 2 had 19 contacts per episode with 0.02, 9 with 0.1)."""
    local_planner: str = "orca"
    """Tracking the slots (Sec. III: [22]'s collision-avoiding MPC): `orca` (controllers.orca), or `cap`: the step
    with the classical approach cap (avoid_distance, avoid_gain, stop_gap), (docs/zhu.md)."""
    target_gap: float = 0.1
    """Ours: targets of two robots closer than 2 r + target_gap are pushed apart (as STAF's plan does); 0: off."""
    orca_horizon: float = ORCA_HORIZON
    orca_margin: float = ORCA_MARGIN
    orca_recovery: float = ORCA_RECOVERY
    n_dead: int = 30
    """n_dead, consecutive control steps of too little progress that flag a stuck robot (Section IV-D)."""
    dp_min: float = 0.15
    """Delta p_min (m): least progress towards its slot over n_dead steps (Section IV-D)."""
    stuck_near: float = 0.4
    """Steps taken within this distance (m) of the slot do not count for stuck detection (the robot is there)."""
    home_slots: bool = True
    """Ours: once p_r has reached the goal, every team that is not left behind out of its sight (`team_reference`),
    not only the whole team merged again, heads for the goal slots one assignment of all robots gives its members;
    false: a subteam fits its own formation round the goal (teams that never merged again, a
    permanent fault or 20 robots too many to merge in their regions, stood there on no goal slot: docs/zhu.md,
    "Teams apart at the goal")."""
    stall_time: float = 3.0
    """Ours (`zhu_decisions.TeamStall`): a team that stays over max_lag from p_r and moves less than dp_min in
    this many seconds splits in two; 0: off. 3 s: the n_dead steps of a stuck robot."""

    def check(self, key: str = "method") -> None:
        require(self.visibility > 0, f"{key}.visibility", "must be > 0 (the visibility radius r_B)", self.visibility)
        require(self.behind > 0, f"{key}.behind", "must be > 0", self.behind)
        require(self.team_lookahead > 0, f"{key}.team_lookahead", "must be > 0", self.team_lookahead)
        require(self.team_wait >= 0, f"{key}.team_wait", "must be >= 0", self.team_wait)
        require(self.horizon >= 0, f"{key}.horizon", "must be >= 0", self.horizon)
        require(
            self.decision_period > 0 and self.control_period > 0,
            f"{key}.decision_period/control_period",
            "must be > 0",
            (self.decision_period, self.control_period),
        )
        require(self.v_min is None or self.v_min > 0, f"{key}.v_min", "must be > 0 or null", self.v_min)
        require(self.visibility_sides >= 4, f"{key}.visibility_sides", "must be >= 4", self.visibility_sides)
        if self.v_min is not None:  # the whole visibility polygon is the largest region a robot can have
            k = self.visibility_sides
            largest = 0.5 * k * self.visibility**2 * math.sin(2 * math.pi / k)
            require(
                self.v_min < largest,
                f"{key}.v_min",
                f"is larger than any region can be ({largest:.1f} m^2 "
                f"for visibility {self.visibility:g} m): the team would split at once and never merge",
                self.v_min,
            )
        require(self.p_max > 0, f"{key}.p_max", "must be > 0", self.p_max)
        require(
            self.local_planner in ("orca", "cap"), f"{key}.local_planner", "must be orca or cap", self.local_planner
        )
        require(
            self.orca_horizon > 0 and self.orca_recovery > 0 and self.orca_margin >= 0 and self.target_gap >= 0,
            f"{key}.orca_horizon/orca_recovery/orca_margin/target_gap",
            "must be > 0 / > 0 / >= 0 / >= 0",
            (self.orca_horizon, self.orca_recovery, self.orca_margin, self.target_gap),
        )
        require(self.max_subteams >= 2, f"{key}.max_subteams", "must be >= 2", self.max_subteams)
        require(
            self.reference_speed > 0 and self.max_lag > 0,
            f"{key}.reference_speed/max_lag",
            "must be > 0",
            (self.reference_speed, self.max_lag),
        )
        require(
            len(self.scales) > 0 and all(0 < s <= 1 for s in self.scales),
            f"{key}.scales",
            "need values in (0, 1]",
            self.scales,
        )
        require(
            self.n_dead >= 1 and self.dp_min > 0 and self.stall_time >= 0,
            f"{key}.n_dead/dp_min/stall_time",
            "must be >= 1, > 0 and >= 0",
            (self.n_dead, self.dp_min, self.stall_time),
        )
