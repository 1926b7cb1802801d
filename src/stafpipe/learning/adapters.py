"""One adapter per learned method: the glue between the harness and the method's network.

An adapter says what the network sees (features), where each robot is heading (the target its progress reward is
measured to, and the goal slot its arrival is judged at), and the method's own reward terms. The PPO rollout
(`rollout.collect`) and the evaluation controller (`controllers/learned.py`) both drive a method only through its
adapter, on batches of worlds (B, n, ...), so training and evaluation cannot drift apart and the trainer has no
method-name branches: a new learned method is a network file, an adapter, a config and its entry in
`stafpipe/registry.py:METHODS`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, NamedTuple

import numpy as np

from stafpipe.controllers.base import TeamInfo
from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.controllers.staf_plan import StafPlan
from stafpipe.learning.config import PolicyConfig, RewardConfig
from stafpipe.learning.features import Features, staf_features
from stafpipe.learning.policy_net import PolicyNet
from stafpipe.learning.staf_net import StafPolicy
from stafpipe.sensing import Observation


class Step(NamedTuple):
    """What an adapter gives for one control step of B worlds."""

    features: Features
    aim: np.ndarray
    """(B, n, 2) the point each robot's progress reward is measured to."""
    targets: np.ndarray
    """(B, n, 2) where each robot is heading (logged as the controller's targets)."""


class Adapter:
    """Base adapter: robots aim at their own goal slots; no reward terms of its own."""

    name: ClassVar[str] = ""
    network: ClassVar[type[PolicyNet]]
    plan_key: ClassVar[str] = "plan"
    """The field of the method's config (and of `train_ppo`) holding the settings passed as `plan`."""

    def __init__(self, policy: PolicyConfig, reward: RewardConfig, plan: Any, sensing_radius: float):
        self.policy, self.reward_cfg, self.plan_cfg, self.sensing_radius = policy, reward, plan, sensing_radius
        self.teams: list[TeamInfo] = []
        self._paths: list[tuple[object, np.ndarray]] = []  # (scenario, its centred path), by identity

    def centred(self, team: TeamInfo) -> np.ndarray:
        """The path through the middle of the passages (episode.centred_path), computed once per scenario."""
        from stafpipe.episode import centred_path
        from stafpipe.geometry import Geometry

        for scenario, path in self._paths:
            if scenario is team.scenario:
                return path
        self._paths.append((team.scenario, centred_path(team.scenario, Geometry.of(team.scenario), team.passage_width)))
        return self._paths[-1][1]

    def begin(self, teams: list[TeamInfo], privileged: bool = False) -> None:
        """Start one episode in each of B worlds; `privileged`: `teacher_aim` may see more than the network."""
        self.teams = teams
        self._aim = np.stack([t.goal for t in teams])

    def teacher_aim(self) -> np.ndarray:
        """(B, n, 2) the point an imitation teacher drives each robot to at the last step (ppo.imitate); by default
        the network's own aim."""
        return self._aim

    def step(self, obs: Observation, dt: float) -> Step:
        raise NotImplementedError

    def features(self, obs: Observation) -> Features:
        """What the network would see in another observation `obs` of the same worlds at the last step's targets
        (the imitation's relabelled copies, ppo._teacher_samples); the plan does not move."""
        raise NotImplementedError

    def goals(self) -> np.ndarray:
        """(B, n, 2) each robot's goal slot now (where arrival is judged)."""
        return np.stack([t.goal for t in self.teams])

    def reward(self, pos: np.ndarray, vel: np.ndarray, obs: Observation) -> np.ndarray:
        """(B, n) the method's own reward terms of this step (beyond progress, arrival and contacts)."""
        return np.zeros(pos.shape[:2])

    def subteams(self) -> np.ndarray:
        """(B, n) subteam id of each robot."""
        return np.zeros((len(self.teams), len(self.teams[0].goal)), dtype=int)

    def drain_events(self, w: int) -> list[tuple[str, list[int], str]]:
        """Events (kind, robots, detail) of world w since the last call."""
        return []


class SubteamAdapter(Adapter):
    """An adapter whose worlds each hold a plan of subteams (`self.plans`: goal, labels, same, expected and events):
    goals, subteams and events are the plan's; the reward adds STAF's R^adp and proximity terms (`staf_penalties`)."""

    plans: list

    def goals(self) -> np.ndarray:
        return np.stack([p.goal for p in self.plans])  # the regroup reassigns the goal slots

    def reward(self, pos: np.ndarray, vel: np.ndarray, obs: Observation) -> np.ndarray:
        radius = self.teams[0].scenario.spec.robot.radius
        return staf_penalties(pos, vel, obs, self.plans, self.reward_cfg, radius)

    def subteams(self) -> np.ndarray:
        return np.array([p.labels for p in self.plans])

    def drain_events(self, w: int) -> list[tuple[str, list[int], str]]:
        return self.plans[w].drain_events()


class StafPlannedAdapter(SubteamAdapter):
    """STAF-planned (ours; STAF Sec. 3, App. B): the plan (deep graph cut, subteams, regroup;
    controllers/staf_plan.py) gives each robot its target; the network sees the robot-frame states of
    `features.staf_features`; the reward adds R^adp and the proximity penalty (`staf_penalties`)."""

    name = "staf_planned"
    network = StafPolicy
    plan_cfg: PlanConfig  # always set here (the default plan when none is given)

    def __init__(self, policy: PolicyConfig, reward: RewardConfig, plan: PlanConfig | None, sensing_radius: float):
        from stafpipe.highlevel.infer import divider

        super().__init__(policy, reward, plan or PlanConfig(), sensing_radius)
        self.divide = divider(self.plan_cfg.high_checkpoint)  # App. B.1: the high level is trained first, then fixed
        self.plans: list[StafPlan] = []

    def begin(self, teams: list[TeamInfo], privileged: bool = False) -> None:
        """`privileged` with `plan.adapt=nominal` (`train_ppo.imitation.privileged`): shadow plans with the geometric
        adaptation run beside the method's own: their targets are the imitation teacher's aim (the network never sees
        them). Otherwise the teacher aims where the network does."""
        super().begin(teams)
        self._diff_drive = np.array([t.scenario.spec.robot.drive == "diff_drive" for t in teams])
        self.plans = [
            StafPlan(self.plan_cfg, t.scenario, t.template, t.goal, self.centred(t), t.passage_width, self.divide)
            for t in teams
        ]
        shadow = dataclasses.replace(self.plan_cfg, adapt="geometric")
        privileged = privileged and self.plan_cfg.adapt != "geometric"  # else the teacher's aim is the plan's own
        self.shadows = (
            [
                StafPlan(shadow, t.scenario, t.template, t.goal, self.centred(t), t.passage_width, self.divide)
                for t in teams
            ]
            if privileged
            else []
        )

    def step(self, obs: Observation, dt: float) -> Step:
        if self.shadows:
            self._aim = np.stack([p.step(obs.position[w], dt) for w, p in enumerate(self.shadows)])
        # np.array stacks a list of equal arrays as np.stack does, at a fraction of its call overhead (every step)
        target = np.array([p.step(obs.position[w], dt) for w, p in enumerate(self.plans)])
        if not self.shadows:
            self._aim = target
        self._target, self._same = target, np.array([p.same for p in self.plans])
        return Step(self.features(obs), target, target)

    def features(self, obs: Observation) -> Features:
        flag = self._diff_drive if self.policy.drive_input else None
        return staf_features(obs, self._target, self._same, self.policy.goal_clip, self.sensing_radius, flag)


def staf_penalties(
    pos: np.ndarray, vel: np.ndarray, obs: Observation, plans: list, rc: RewardConfig, radius: float
) -> np.ndarray:
    """(B, n) STAF's formation and proximity terms of this step. R^adp (STAF Sec. 3) over the robot's subteam mates,
    -lambda |d_ij - p_ij| - (1 - lambda) q_ij with d_ij from the plan's formation, averaged over the mates so that
    subteams of any size weigh alike; proximity: linear in how far a gap is below `safe_distance`
    (docs/staf_planned.md)."""
    n = pos.shape[1]
    expected = np.stack([p.expected for p in plans])
    same = np.stack([p.same for p in plans]) & ~np.eye(n, dtype=bool)
    dist = np.linalg.norm(pos[:, :, None] - pos[:, None], axis=-1)
    q = np.linalg.norm(vel[:, :, None] - vel[:, None], axis=-1)
    pair = -rc.adp_lambda * np.abs(expected - dist) - (1.0 - rc.adp_lambda) * q
    adp = (pair * same).sum(-1) / np.maximum(same.sum(-1), 1)
    gap = dist - 2 * radius + np.eye(n) * 1e9
    near = np.clip(1.0 - gap / rc.safe_distance, 0.0, 1.0).sum(-1)
    near += np.clip(1.0 - obs.obstacle_distance / rc.safe_distance, 0.0, 1.0)
    return rc.formation * adp - rc.proximity * near
