"""STAF's adapter (STAF, Sec. 3 and App. B): the rules of `subteaming.py` give every robot its goal; the network
(phi + psi, learning/staf_net.py) sees each robot's state s_i = [goal, velocity, closest obstacle] in its own frame
and its teammates' differences s_j - s_i within the communication radius; the reward adds R^adp over subteam mates
and the proximity penalty to the harness' navigation terms (App. B.1). Training (`train_ppo.method=staf`) and
evaluation (`method=staf`) both drive the method through this class."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from stafpipe.controllers.base import TeamInfo
from stafpipe.learning.adapters import Step, SubteamAdapter
from stafpipe.learning.config import PolicyConfig, RewardConfig
from stafpipe.learning.features import Features, staf_features
from stafpipe.learning.staf_net import StafPolicy
from stafpipe.methods.staf.subteaming import SubteamingConfig, SubteamPlan
from stafpipe.sensing import Observation


class StafAdapter(SubteamAdapter):
    """STAF as the paper describes it: subteams by the deep graph cut, goals by rule, formation keeping learned."""

    name = "staf"
    network = StafPolicy
    plan_key: ClassVar[str] = "subteaming"
    plan_cfg: SubteamingConfig

    def __init__(self, policy: PolicyConfig, reward: RewardConfig, plan: object, sensing_radius: float):
        from stafpipe.highlevel.checkpoint import load_checkpoint

        plan = plan if isinstance(plan, SubteamingConfig) else SubteamingConfig()
        super().__init__(policy, reward, None, sensing_radius)
        self.plan_cfg = plan
        self.model, _ = load_checkpoint(plan.high_checkpoint)  # App. B.1: the high level is trained first, then fixed
        self.plans: list[SubteamPlan] = []
        self.messages = True
        """False: every neighbour mask empty, so phi's message sum is zero (`method.messages=false`)."""

    def cut(self, start: np.ndarray, goal: np.ndarray, m: int) -> np.ndarray:
        """The deep graph cut's subteam probabilities Y (n, m) for a team at `start` heading for `goal` (Eq. (1))."""
        from stafpipe.highlevel.graphs import Team
        from stafpipe.highlevel.infer import predict

        m = min(m, self.model.cfg.m_max)
        return predict(self.model, [Team(np.asarray(start, float), np.asarray(goal, float), m)])[0][:, :m]

    def begin(self, teams: list[TeamInfo], privileged: bool = False) -> None:
        from stafpipe.episode import narrow_stretches
        from stafpipe.geometry import Geometry

        super().begin(teams)
        self._diff_drive = np.array([t.scenario.spec.robot.drive == "diff_drive" for t in teams])
        self.plans = []
        for t in teams:
            spec, path = t.scenario.spec, self.centred(t)
            passages = narrow_stretches(t.scenario, Geometry.of(t.scenario), path, self.plan_cfg.wall_margin)
            self.plans.append(
                SubteamPlan(
                    self.plan_cfg,
                    spec.team.formation,
                    spec.team.angle_deg,
                    spec.team.spacing,
                    spec.robot.radius,
                    math.radians(spec.team.heading_deg),
                    t.start,
                    t.goal,
                    path,
                    passages,
                    t.passage_width,
                    self.cut,
                )
            )

    def step(self, obs: Observation, dt: float) -> Step:
        target = np.array([p.step(obs.position[w]) for w, p in enumerate(self.plans)])
        self._pos = obs.position
        self._aim = self._target = target
        self._same = np.array([p.same for p in self.plans])
        return Step(self.features(obs), target, target)

    def teacher_aim(self) -> np.ndarray:
        """The imitation teacher's aim (`subteaming.teacher_aim`): the robot's target or the nearest point to it that
        is clear of the walls and in a straight line from the robot; the teacher reads the map, the network does
        not."""
        from stafpipe.geometry import Geometry
        from stafpipe.methods.staf.subteaming import teacher_aim

        out = np.empty_like(self._target)
        for w, (team, plan) in enumerate(zip(self.teams, self.plans, strict=True)):
            radius = team.scenario.spec.robot.radius
            clearance = Geometry.of(team.scenario).clearance
            keep = radius + self.plan_cfg.wall_margin
            out[w] = teacher_aim(
                self._pos[w],
                self._target[w],
                plan.centre,
                plan.progress,
                plan.frame,
                clearance,
                radius,
                keep,
                plan.labels,
            )
        return out

    def features(self, obs: Observation) -> Features:
        flag = self._diff_drive if self.policy.drive_input else None
        f = staf_features(obs, self._target, self._same, self.policy.goal_clip, self.sensing_radius, flag)
        return f if self.messages else f._replace(mask=np.zeros_like(f.mask))
