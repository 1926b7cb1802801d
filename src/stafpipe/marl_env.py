"""stafpipe's world as a multi-agent environment for other people's training code (docs/marl_env.md).

- `BatchedTeamEnv`: B worlds stepped together, arrays (B, n, ...) in and out: the fast form, as our trainer uses.
- `TeamParallelEnv`: a PettingZoo `ParallelEnv` (one world, agents `robot_0` ... `robot_{n-1}`) over the batched form.

Both give exactly what `stafpipe train-ppo` trains on: the learned method's features (`method`: `dgnn` or
`staf_planned`, its adapter in learning/adapters.py, so STAF-planned's plan sets the targets), its per-robot reward
(`rollout.step_reward`: progress, arrival bonus, contacts, the method's own terms) and its episodes: a fixed length of
`episode_steps`, cut by truncation, never terminated early. An action is a robot-frame velocity in units of top speed,
clipped to [-1, 1]. At the end of an episode the info carries the trainer's metrics (`rollout.episode_stats`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from stafpipe.learning.config import PolicyConfig, RewardConfig
from stafpipe.learning.features import flat_rows
from stafpipe.learning.ppo import teams_of
from stafpipe.learning.rollout import commands, episode_stats, step_reward, world_routes
from stafpipe.registry import adapter_class, learned_methods
from stafpipe.scenario import build_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig, Worlds


class BatchedTeamEnv:
    """B copies of one scenario (a built-in name or a scenario file), stepped together."""

    def __init__(
        self,
        scenario: str = "corridor",
        worlds: int = 1,
        method: str = "dgnn",
        episode_steps: int = 400,
        formation: str | None = None,
        n: int | None = None,
        goal_tolerance: float = 0.3,
        world: WorldConfig | None = None,
        sensing: SensingConfig | None = None,
        reward: RewardConfig | None = None,
        policy: PolicyConfig | None = None,
        plan: Any = None,
    ) -> None:
        from stafpipe.errors import StafpipeError
        from stafpipe.scenario_pool import load_named_scenario, path_and_width

        if method not in learned_methods():
            raise StafpipeError(f"method must be one of {learned_methods()}, got {method!r}")
        if worlds < 1 or episode_steps < 1:
            raise StafpipeError(f"worlds and episode_steps must be >= 1, got {worlds} and {episode_steps}")
        sc = load_named_scenario(scenario)
        if formation or n:
            team = dataclasses.replace(
                sc.spec.team, formation=formation or sc.spec.team.formation, n=n or sc.spec.team.n
            )
            sc = build_scenario(dataclasses.replace(sc.spec, team=team))
        self.scenario, self.size, self.episode_steps = sc, worlds, episode_steps
        self.world_cfg, self.sensing = world or WorldConfig(), sensing or SensingConfig()
        self.reward_cfg, self.tolerance = reward or RewardConfig(), goal_tolerance
        self.adapter = adapter_class(method)(policy or PolicyConfig(), self.reward_cfg, plan, self.sensing.radius)
        self.drawn = [(sc, *path_and_width(sc))] * worlds
        self.worlds = Worlds([sc] * worlds, self.sensing, self.world_cfg)
        self.n = self.worlds.n
        self.t = 0

    def reset(self, seed: int = 0) -> dict[str, np.ndarray]:
        """Start every world (world w from seed `seed + w`); the features of the first step."""
        self.obs = self.worlds.reset([seed + w for w in range(self.size)])
        self.adapter.begin(teams_of(self.drawn, self.worlds))
        self.dist = np.linalg.norm(self.adapter.goals() - self.worlds.pos, axis=-1)
        self.route = world_routes(self.worlds)
        self.reached = (self.dist <= self.tolerance) & self.route.update(self.worlds.pos)[:, None]
        self.hits, self.t = 0, 0
        self.returns = np.zeros((self.size, self.n))
        return self._features()

    def _features(self) -> dict[str, np.ndarray]:
        self._step_info = self.adapter.step(self.obs, self.world_cfg.control_dt)
        f = self._step_info.features
        return {"own": f.own, "edge": f.edge, "mask": f.mask}

    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, bool, dict[str, float]]:
        """Act (B, n, 2); the next features, rewards (B, n), whether the episode is over (truncated), and at its end
        the trainer's metrics."""
        aim = self._step_info.aim
        before = np.linalg.norm(aim - self.worlds.pos, axis=-1)
        self.obs, events = self.worlds.step(
            commands(np.asarray(actions, float), self.worlds.heading, self.worlds.robot.max_speed)
        )
        self.hits += sum(len(e) for e in events)
        reward, self.dist, self.reached = step_reward(
            self.adapter, self.worlds, self.obs, aim, before, self.reached, self.tolerance, self.reward_cfg, self.route
        )
        self.returns += reward
        self.t += 1
        done = self.t >= self.episode_steps
        info = (
            episode_stats(self.worlds, self.dist, self.reached, self.tolerance, self.hits, self.returns) if done else {}
        )
        return self._features(), reward, done, info


def _pettingzoo_env() -> type:
    """TeamParallelEnv, built on first use so that stafpipe imports without PettingZoo (the `marl` extra)."""
    from gymnasium import spaces
    from pettingzoo import ParallelEnv

    class TeamParallelEnv(ParallelEnv):
        """One world; each robot an agent whose observation is its row of the method's features, flattened:
        own (F), then for each robot j its edge features (E) and whether it is a neighbour (1): F + n (E + 1)."""

        metadata = {"name": "stafpipe_team_v0", "render_modes": []}  # noqa: RUF012 (PettingZoo's convention)

        def __init__(self, **kwargs: Any) -> None:
            self.batched = BatchedTeamEnv(worlds=1, **kwargs)
            self.possible_agents = [f"robot_{i}" for i in range(self.batched.n)]
            self.agents: list[str] = []
            probe = self.batched.reset(0)
            self._size = probe["own"].shape[-1] + self.batched.n * (probe["edge"].shape[-1] + 1)
            self._obs_space = spaces.Box(-np.inf, np.inf, (self._size,), np.float32)
            self._act_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
            self._seed = 0

        def observation_space(self, agent: str) -> spaces.Box:
            return self._obs_space

        def action_space(self, agent: str) -> spaces.Box:
            return self._act_space

        def _observe(self, feats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
            flat = flat_rows(feats["own"][0], feats["edge"][0], feats["mask"][0])
            return {a: flat[i].astype(np.float32) for i, a in enumerate(self.possible_agents)}

        def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
            if seed is not None:
                self._seed = int(seed)
            self.agents = list(self.possible_agents)
            obs = self._observe(self.batched.reset(self._seed))
            self._seed += 1  # the next reset without a seed starts another episode
            return obs, {a: {} for a in self.agents}

        def step(self, actions: dict[str, np.ndarray]) -> tuple[dict, dict, dict, dict, dict]:
            act = np.zeros((1, self.batched.n, 2))
            for i, a in enumerate(self.possible_agents):
                if a in actions:
                    act[0, i] = actions[a]
            feats, reward, done, stats = self.batched.step(act)
            agents = self.agents
            obs = self._observe(feats)
            rewards = {a: float(reward[0, i]) for i, a in enumerate(self.possible_agents) if a in agents}
            infos = {a: dict(stats) for a in agents}
            terminations = dict.fromkeys(agents, False)
            truncations = dict.fromkeys(agents, done)
            if done:
                self.agents = []
            return {a: obs[a] for a in agents}, rewards, terminations, truncations, infos

    return TeamParallelEnv


def parallel_env(**kwargs: Any) -> Any:
    """A PettingZoo ParallelEnv over one stafpipe world (arguments as BatchedTeamEnv's, without `worlds`)."""
    return _pettingzoo_env()(**kwargs)
