"""`method=staf_planned`: STAF-planned, ours, not the paper's method: the STAF hierarchy (STAF, App. B.2 execution)
driven by a hand-written plan. The plan (controllers/staf_plan.py: deep graph cut when a passage ahead is too narrow,
subteams in the team's formation type passing one after another, regroup into the original formation) gives every
robot its target; the trained intermediate GNN + low-level policy (learning/staf_net.py, `stafpipe train-ppo
train_ppo.method=staf_planned`) drives it there, adapting the formation to the passage and keeping clear of robots and
walls. Driven through `learning/adapters.py:StafPlannedAdapter`, as in training."""

from __future__ import annotations

from dataclasses import dataclass, field

from stafpipe.config.checks import LearnedMethodChecks
from stafpipe.controllers.learned import LearnedController
from stafpipe.controllers.plan_config import PlanConfig


@dataclass
class StafMethodConfig(LearnedMethodChecks):
    """Config of `method=staf_planned` (group `method`)."""

    name: str = "staf_planned"
    checkpoint: str = ""
    """A `policy.pt` of `stafpipe train-ppo train_ppo.method=staf_planned`; empty: the one shipped with the package;
    `shipped:NAME`: NAME.pt shipped with it."""
    deterministic: bool = True
    """Act with the policy's mean (as evaluated); false samples from it."""
    sensing_radius: float = 2.0
    """Must equal the `sensing.radius` the policy was trained with (features clip the obstacle vector to it)."""
    allow_mismatch: bool = False
    """Run a checkpoint whose recorded training settings (plan, sensing radius) differ from this run's, with a
    warning naming each differing key; false refuses it (learned/controllers: checkpoint_mismatch)."""
    ensemble: list[str] | None = None
    """More `policy.pt` files of the same network (other training runs, e.g. other seeds): each robot acts with the mean
    of their action means and the checkpoint's. Unset (default): with the shipped checkpoint (`checkpoint` empty) the
    shipped pair, `staf_planned.pt` + `staf_planned_seed1.pt`; with any other checkpoint, that checkpoint alone. `[]`:
    the checkpoint alone (`checkpoint=shipped:staf_planned ensemble=[]` is the shipped first run by itself). Each member
    is checked as the checkpoint is (settings, `allow_mismatch`)."""
    low_level: str = "learned"
    """`learned` (phi + psi, the trained policy); or no learning below the plan (the ablation of docs/staf_planned.md,
    `staf_levels`): `proportional` (each robot steps towards its target at min(1, gain x distance) of top speed),
    `avoiding` (the same with the classical methods' approach cap near robots and obstacles), `sliding` (`avoiding`
    aiming no closer to the closest obstacle than a margin) or `orca` (the same step as ORCA's preferred velocity);
    learning/teachers.py."""
    proportional_gain: float = 2.0
    """low_level other than learned: the step's gain (1/s)."""
    stop_gap: float = 0.02
    """low_level other than learned: the gap (m) its approach cap brakes to (as `train_ppo.imitation.stop_gap`)."""
    approach_cap: bool = False
    """A safety layer on the commands, not in STAF's paper (whose action is psi's alone): towards any robot or obstacle
    closer than 0.35 m the approach speed is capped at 2 x (gap - `approach_cap_gap`), and on a differential drive the
    motion the drive makes from the command too (the classical methods' cap, controllers/base.py `limit_approach`,
    `forward_capped`). Any low level, learned or hand-made, gets it alike
    (the STAF-planned journal (docs/staf_planned.md), "A safety layer")."""
    approach_cap_gap: float = 0.02
    """approach_cap: the gap (m) it brakes to."""
    avoid_movers: bool = True
    """Moving obstacles (a walking human) avoided by a safety layer on the commands, ORCA's half-planes of the movers
    alone (controllers/orca.py `avoid_movers`): neither the plan nor the network sees a mover's velocity. Not in the
    STAF paper, which has no moving obstacles; no effect on a map without them
    (the STAF-planned journal (docs/staf_planned.md), "Moving obstacles")."""
    plan: PlanConfig = field(default_factory=PlanConfig)
    """Subteams, sequencing and regroup; keep the settings the policy was trained with (its `made_by` records them)."""

    def check(self, key: str = "method") -> None:
        self.check_low_level(key, self.stop_gap)
        self.plan.check(f"{key}.plan")


class StafController(LearnedController):
    """Plan + shared policy for every robot of one world."""
