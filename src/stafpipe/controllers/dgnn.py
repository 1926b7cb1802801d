"""`method=dgnn`: the DGNN baseline (Blumenkamp et al., ICRA 2022) as STAF compares with it: a decentralized GNN policy
trained by `stafpipe train-ppo` with navigation and collision rewards only, no formation term. Each robot drives to its
own goal slot; no subteams."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from stafpipe.controllers.base import Controller, TeamInfo
from stafpipe.learning.checkpoint import load_policy
from stafpipe.learning.features import features, guide_targets
from stafpipe.learning.rollout import commands
from stafpipe.sensing import Observation


@dataclass
class DGNNConfig:
    """Config of `method=dgnn` (group `method`)."""

    name: str = "dgnn"
    checkpoint: str = ""
    """A `policy.pt` of `stafpipe train-ppo`; empty: the one shipped with the package."""
    deterministic: bool = True
    """Act with the policy's mean (as evaluated); false samples from it."""
    sensing_radius: float = 2.0
    """Must equal the `sensing.radius` the policy was trained with (features clip the obstacle vector to it)."""


class DGNNController(Controller):
    """Runs the trained policy for every robot of one world."""

    def __init__(self, cfg: DGNNConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.policy, self.made_by = load_policy(cfg.checkpoint, "dgnn")
        self.max_speed = 1.0
        self.generator = torch.Generator().manual_seed(0)
        self.path = np.zeros((0, 2))

    def reset(self, team: TeamInfo) -> None:
        super().reset(team)
        self.max_speed = team.scenario.spec.robot.max_speed
        self.path = team.path

    def act(self, obs: Observation) -> np.ndarray:
        pc = self.policy.cfg
        target = guide_targets(obs.position, obs.goal, self.path, pc.lookahead, pc.release) if pc.guide == "path" else None
        if target is not None:
            self._targets = target
        f = features(obs, pc.goal_clip, self.cfg.sensing_radius, target)
        with torch.no_grad():
            mean, _ = self.policy(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
            if not self.cfg.deterministic:
                mean = mean + self.policy.log_std.exp() * torch.randn(mean.shape, generator=self.generator)
        return commands(mean.numpy(), obs.heading, self.max_speed)
