"""The evaluation controller of every learned method: its policy checkpoint driven through the method's adapter
(learning/adapters.py), exactly as the PPO rollout drives it, one world at a time."""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np
import torch

from stafpipe.controllers.base import Controller, TeamInfo
from stafpipe.errors import StafpipeError
from stafpipe.learning.adapters import ADAPTERS
from stafpipe.learning.checkpoint import load_policy
from stafpipe.learning.config import RewardConfig
from stafpipe.learning.rollout import commands
from stafpipe.learning.teachers import teacher_actions
from stafpipe.sensing import Observation

log = logging.getLogger(__name__)


PLAN_SAFEGUARDS = ("home", "target_gap", "home_approach")
"""Plan settings that only keep targets from crossing, crowding or running into robots already home (docs/staf.md): a
policy trained without them runs with them, so they are not compared with its training record."""


def checkpoint_mismatch(cfg: Any, made_by: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    """Settings of this run that differ from those the checkpoint recorded at training (`made_by`): the plan
    (`method.plan.*` against `train_ppo.plan.*`) and the sensing radius (against `sensing.radius`), as far as the
    checkpoint recorded them. Key -> (this run's value, the training value)."""
    trained = made_by.get("train_ppo", {})
    differ: dict[str, tuple[Any, Any]] = {}
    plan, recorded = getattr(cfg, "plan", None), trained.get("plan")
    if plan is not None and isinstance(recorded, dict):
        for key, value in dataclasses.asdict(plan).items():
            if key in recorded and recorded[key] != value and key not in PLAN_SAFEGUARDS:
                differ[f"method.plan.{key}"] = (value, recorded[key])
    radius = made_by.get("sensing", {}).get("radius")
    if radius is not None and float(radius) != float(cfg.sensing_radius):
        differ["method.sensing_radius"] = (cfg.sensing_radius, radius)
    return differ


class LearnedController(Controller):
    """A learned method (`cfg.name` names its adapter) acting with its policy's mean, or sampling if
    `cfg.deterministic` is false. `cfg.low_level` other than `learned` (where the config has it) replaces the
    network's action by a hand-made low level (learning/teachers.py): the method with its learned part removed."""

    def __init__(self, cfg: Any) -> None:  # a method config dataclass (DGNNConfig, StafMethodConfig)
        super().__init__()
        check = getattr(cfg, "check", None)
        if check:
            check()
        self.cfg = cfg
        self.policy, self.made_by = load_policy(cfg.checkpoint, cfg.name)
        self.teacher = getattr(cfg, "low_level", "learned")  # `learned`, or a hand-made low level (teachers.py)
        differ = checkpoint_mismatch(cfg, self.made_by) if self.teacher == "learned" else {}
        if differ:
            text = "; ".join(f"{k}: this run {a!r}, trained with {b!r}" for k, (a, b) in differ.items())
            where = cfg.checkpoint or f"the shipped {cfg.name} policy"
            if not getattr(cfg, "allow_mismatch", False):
                raise StafpipeError(
                    f"{where} was trained with other settings than this run ({text}); retrain it, "
                    "or set method.allow_mismatch=true to run it anyway"
                )
            log.warning("%s was trained with other settings than this run: %s", where, text)
        self.adapter = ADAPTERS[cfg.name](
            self.policy.cfg, RewardConfig(), getattr(cfg, "plan", None), cfg.sensing_radius
        )
        self.generator = torch.Generator().manual_seed(0)
        # One thread: a parallel matrix product sums in another order, and a closed loop grows the last bit into
        # another trajectory (measured: DGNN's corridor wedge, 1 vs 2 threads, other TT in 4 of 5 episodes). With
        # one thread the seed fixes the episode on any number of cores; these networks are no slower with it.
        torch.set_num_threads(1)
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
            mean = teacher_actions(
                self.teacher, targets - batch.position, batch, radius, self.max_speed, self.cfg.proportional_gain
            )
            return commands(mean[0], obs.heading, self.max_speed)
        with torch.inference_mode():  # execution: no critic, no autograd bookkeeping
            action = self.policy.act(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
            if not self.cfg.deterministic:
                action = action + self.policy.log_std.exp() * torch.randn(action.shape, generator=self.generator)
        return commands(action[0].numpy(), obs.heading, self.max_speed)
