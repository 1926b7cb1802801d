"""The evaluation controller of every learned method: its policy checkpoint driven through the method's adapter
(learning/adapters.py), exactly as the PPO rollout drives it, one world at a time."""

from __future__ import annotations

import numpy as np
import torch

from stafpipe.controllers.base import Controller, TeamInfo
from stafpipe.learning.adapters import ADAPTERS
from stafpipe.learning.checkpoint import load_policy
from stafpipe.learning.config import RewardConfig
from stafpipe.learning.rollout import commands
from stafpipe.learning.teachers import teacher_actions
from stafpipe.sensing import Observation


class LearnedController(Controller):
    """A learned method (`cfg.name` names its adapter) acting with its policy's mean, or sampling if
    `cfg.deterministic` is false. `cfg.low_level` other than `learned` (where the config has it) replaces the
    network's action by a hand-made low level (learning/teachers.py): the method with its learned part removed."""

    def __init__(self, cfg) -> None:  # noqa: ANN001 - a method config dataclass (DGNNConfig, StafMethodConfig)
        super().__init__()
        check = getattr(cfg, "check", None)
        if check:
            check()
        self.cfg = cfg
        self.policy, self.made_by = load_policy(cfg.checkpoint, cfg.name)
        self.adapter = ADAPTERS[cfg.name](self.policy.cfg, RewardConfig(), getattr(cfg, "plan", None),
                                          cfg.sensing_radius)
        self.teacher = getattr(cfg, "low_level", "learned")  # `learned`, or a hand-made low level (teachers.py)
        self.generator = torch.Generator().manual_seed(0)
        self.max_speed = 1.0
        self.last_time = 0.0

    def reset(self, team: TeamInfo) -> None:
        super().reset(team)
        self.max_speed = team.scenario.spec.robot.max_speed
        self.adapter.begin([team])
        self.last_time = 0.0

    def act(self, obs: Observation) -> np.ndarray:
        dt, self.last_time = float(obs.time) - self.last_time, float(obs.time)
        batch = Observation(*(np.asarray(x)[None] for x in obs))  # a batch of one world, as the adapter takes
        f, _, targets = self.adapter.step(batch, dt)
        self._targets = targets[0].copy()
        self._subteams = self.adapter.subteams()[0].copy()
        for kind, robots, detail in self.adapter.drain_events(0):
            self.emit(kind, robots, detail)
        if self.teacher != "learned":
            radius = self.adapter.teams[0].scenario.spec.robot.radius
            mean = teacher_actions(self.teacher, targets - batch.position, batch, radius, self.max_speed,
                                   self.cfg.proportional_gain)
            return commands(mean[0], obs.heading, self.max_speed)
        with torch.inference_mode():  # execution: no critic, no autograd bookkeeping
            mean = self.policy.act(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
            if not self.cfg.deterministic:
                mean = mean + self.policy.log_std.exp() * torch.randn(mean.shape, generator=self.generator)
        return commands(mean[0].numpy(), obs.heading, self.max_speed)
