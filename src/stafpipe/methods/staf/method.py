"""`method=staf`: STAF as the paper describes it (STAF, Sec. 3, App. B.2 execution). The deep graph cut divides the
team into the smallest number of balanced subteams whose formations fit the narrowest passage (Sec. 7), every
subteam heads for goal slots of its own same-type formation, and once all are through the goals switch back to the
full team's (subteaming.py); phi + psi (learning/staf_net.py), trained by PPO with R^adp (`stafpipe run staf_train`),
drive every robot towards its goal, keeping and adapting its subteam's formation. Driven through
`methods/staf/adapter.py:StafAdapter`, as in training."""

from __future__ import annotations

from dataclasses import dataclass, field

from stafpipe.config.checks import LearnedMethodChecks
from stafpipe.controllers.learned import LearnedController
from stafpipe.methods.staf.subteaming import SubteamingConfig


@dataclass
class StafConfig(LearnedMethodChecks):
    """Config of `method=staf` (group `method`)."""

    name: str = "staf"
    checkpoint: str = ""
    """A `policy.pt` of `stafpipe train-ppo train_ppo.method=staf`; empty: the one shipped with the package;
    `shipped:NAME`: NAME.pt shipped with it."""
    deterministic: bool = True
    """Act with the policy's mean (as evaluated); false samples from it."""
    sensing_radius: float = 2.0
    """Must equal the `sensing.radius` the policy was trained with (STAF App. C: edges within 2 m)."""
    allow_mismatch: bool = False
    """Run a checkpoint whose recorded training settings (`subteaming`, sensing radius) differ from this run's, with a
    warning naming each differing key; false refuses it."""
    ensemble: list[str] | None = None
    """More `policy.pt` files of the same network whose action means are averaged with the checkpoint's; unset or
    `[]`: the checkpoint alone."""
    low_level: str = "learned"
    """`learned` (phi + psi); or a hand-made low level instead of the network, for the ablations: `orca` is the
    imitation teacher of the warm start (ORCA towards each robot's goal pulled clear of the walls), `proportional`,
    `avoiding`, `sliding` (learning/teachers.py)."""
    proportional_gain: float = 2.0
    """low_level other than learned: the step's gain (1/s)."""
    stop_gap: float = 0.02
    """low_level other than learned: the gap (m) its approach cap brakes to."""
    approach_cap: bool = False
    """A safety layer on the commands, not in the paper: the classical methods' approach cap (controllers/base.py)."""
    approach_cap_gap: float = 0.02
    """approach_cap: the gap (m) it brakes to."""
    avoid_movers: bool = False
    """A safety layer for moving obstacles (controllers/orca.py `avoid_movers`), not in the paper, which has none."""
    messages: bool = True
    """false: phi's messages zeroed at evaluation (no robot hears its neighbours), the ablation of what they carry."""
    subteaming: SubteamingConfig = field(default_factory=SubteamingConfig)
    """Subteams, their goals, the regroup (subteaming.py); the settings the policy was trained with (`made_by`)."""

    def check(self, key: str = "method") -> None:
        self.check_low_level(key, self.stop_gap)
        self.subteaming.check(f"{key}.subteaming")


class StafController(LearnedController):
    """Subteaming rules + the shared learned policy for every robot of a batch of worlds."""

    def __init__(self, cfg: StafConfig) -> None:
        super().__init__(cfg)
        self.adapter.messages = cfg.messages  # type: ignore[attr-defined]  # a StafAdapter (the registry's "staf")
