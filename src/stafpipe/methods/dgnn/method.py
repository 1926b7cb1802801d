"""`method=dgnn`: the DGNN baseline (Blumenkamp et al., ICRA 2022) as STAF compares with it: a decentralized GNN policy
trained by `stafpipe train-ppo` with navigation and collision rewards only, no formation term. Each robot drives to its
own goal slot; no subteams. Driven through `methods/dgnn/adapter.py:DGNNAdapter`, as in training."""

from __future__ import annotations

from dataclasses import dataclass

from stafpipe.config.checks import LearnedMethodChecks
from stafpipe.controllers.learned import LearnedController


@dataclass
class DGNNConfig(LearnedMethodChecks):
    """Config of `method=dgnn` (group `method`)."""

    name: str = "dgnn"
    checkpoint: str = ""
    """A `policy.pt` of `stafpipe train-ppo`; empty: the one shipped with the package."""
    deterministic: bool = True
    """Act with the policy's mean (as evaluated); false samples from it."""
    sensing_radius: float = 2.0
    """Must equal the `sensing.radius` the policy was trained with (features clip the obstacle vector to it)."""
    allow_mismatch: bool = False
    """Run a checkpoint whose recorded training settings (plan, sensing radius) differ from this run's, with a
    warning naming each differing key; false refuses it (learned/controllers: checkpoint_mismatch)."""
    ensemble: list[str] | None = None
    """More `policy.pt` files of the same network (other training runs, e.g. other seeds): each robot acts with the
    mean of their action means and the checkpoint's; unset or empty (default): the checkpoint alone (one DGNN run
    ships). Each is checked as the checkpoint is (settings, `allow_mismatch`)."""
    low_level: str = "learned"
    """`learned` (the trained policy); or the method with its learned part removed (learning/teachers.py):
    `proportional` (a step towards the robot's guided goal), `avoiding` (the same with the classical methods'
    approach cap near robots and obstacles) or `orca` (the same step as ORCA's preferred velocity: the teacher of the
    shipped DGNN's warm start, docs/learning.md)."""
    proportional_gain: float = 2.0
    """low_level other than learned: the step's gain (1/s)."""
    approach_cap: bool = False
    """The safety layer of `method=staf_planned`'s `approach_cap` (approach speed capped near robots and obstacles);
    off, as DGNN's paper acts (the STAF-planned journal (docs/staf_planned.md), "A safety layer")."""
    approach_cap_gap: float = 0.02
    """approach_cap: the gap (m) it brakes to."""
    avoid_movers: bool = True
    """Moving obstacles avoided by the safety layer `method=staf_planned` has (controllers/orca.py `avoid_movers`), so
    that the two learned methods are compared alike; no effect on a map without movers
    (the STAF-planned journal (docs/staf_planned.md), "Moving
    obstacles")."""

    def check(self, key: str = "method") -> None:
        self.check_low_level(key)


class DGNNController(LearnedController):
    """The trained DGNN policy for every robot of one world."""
