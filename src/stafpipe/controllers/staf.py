"""`method=staf`: the full STAF hierarchy (000_f89c49495043d27c.txt; App. B.2 execution). The plan
(controllers/staf_plan.py: deep graph cut when a passage ahead is too narrow, subteams in the team's formation type
passing one after another, regroup into the original formation) gives every robot its target; the trained
intermediate GNN + low-level policy (learning/staf_net.py, `stafpipe train-ppo train_ppo.method=staf`) drives it there
while keeping the formation and clear of robots and walls."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from stafpipe.controllers.base import Controller, TeamInfo
from stafpipe.controllers.staf_plan import PlanConfig, StafPlan
from stafpipe.learning.checkpoint import load_policy
from stafpipe.learning.features import staf_features
from stafpipe.learning.rollout import commands
from stafpipe.sensing import Observation


@dataclass
class StafMethodConfig:
    """Config of `method=staf` (group `method`)."""

    name: str = "staf"
    checkpoint: str = ""
    """A `policy.pt` of `stafpipe train-ppo train_ppo.method=staf`; empty: the one shipped with the package."""
    deterministic: bool = True
    """Act with the policy's mean (as evaluated); false samples from it."""
    sensing_radius: float = 2.0
    """Must equal the `sensing.radius` the policy was trained with (features clip the obstacle vector to it)."""
    plan: PlanConfig = field(default_factory=PlanConfig)
    """Subteams, sequencing and regroup; keep the settings the policy was trained with (its `made_by` records them)."""

    def check(self, key: str = "method") -> None:
        self.plan.check(f"{key}.plan")


class StafController(Controller):
    """Plan + shared policy for every robot of one world."""

    def __init__(self, cfg: StafMethodConfig) -> None:
        super().__init__()
        from stafpipe.highlevel.infer import divider

        cfg.check()
        self.cfg = cfg
        self.policy, self.made_by = load_policy(cfg.checkpoint, "staf")
        self.divide = divider(cfg.plan.high_checkpoint)
        self.generator = torch.Generator().manual_seed(0)
        self.max_speed = 1.0
        self.plan: StafPlan | None = None
        self.last_time = 0.0
        self.paths: list[tuple[object, np.ndarray]] = []  # (scenario, its centred path), by identity

    def reset(self, team: TeamInfo) -> None:
        super().reset(team)
        self.max_speed = team.scenario.spec.robot.max_speed
        self.plan = StafPlan(self.cfg.plan, team.scenario, team.template, team.goal, self._path(team),
                             team.passage_width, self.divide)
        self.last_time = 0.0

    def _path(self, team: TeamInfo) -> np.ndarray:
        """The path through the middle of the passages (episode.centred_path), computed once per scenario."""
        from stafpipe.episode import centred_path
        from stafpipe.geometry import Geometry

        for scenario, path in self.paths:
            if scenario is team.scenario:
                return path
        self.paths.append((team.scenario, centred_path(team.scenario, Geometry(team.scenario), team.passage_width)))
        return self.paths[-1][1]

    def act(self, obs: Observation) -> np.ndarray:
        assert self.plan is not None, "reset() first"
        dt, self.last_time = float(obs.time) - self.last_time, float(obs.time)
        self._targets = self.plan.step(obs.position, dt).copy()
        self._subteams = self.plan.labels.copy()
        for kind, robots, detail in self.plan.drain_events():
            self.emit(kind, robots, detail)
        f = staf_features(obs, self._targets, self.plan.same, self.policy.cfg.goal_clip, self.cfg.sensing_radius)
        with torch.inference_mode():  # execution: no critic, no autograd bookkeeping
            mean = self.policy.act(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
            if not self.cfg.deterministic:
                mean = mean + self.policy.log_std.exp() * torch.randn(mean.shape, generator=self.generator)
        return commands(mean.numpy(), obs.heading, self.max_speed)
