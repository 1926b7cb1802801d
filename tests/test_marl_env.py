"""The multi-agent environment gives what the trainer trains on: PettingZoo's API test, seeded determinism, and the
trainer's own rewards step for step."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stafpipe.learning.checkpoint import build_policy
from stafpipe.learning.config import PolicyConfig, RewardConfig, TrainPPOConfig
from stafpipe.learning.ppo import teams_of
from stafpipe.learning.rollout import collect
from stafpipe.marl_env import BatchedTeamEnv
from stafpipe.registry import adapter_class
from stafpipe.scenario_pool import load_named_scenario, path_and_width
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig, Worlds

pettingzoo = pytest.importorskip("pettingzoo")  # the `marl` extra (installed with `test`)


@pytest.mark.parametrize(("method", "formation"), [("dgnn", None), ("staf_planned", "wedge")])
def test_parallel_env_passes_the_pettingzoo_api_test(method, formation) -> None:
    from pettingzoo.test import parallel_api_test

    from stafpipe.marl_env import parallel_env

    env = parallel_env(scenario="corridor", method=method, formation=formation, episode_steps=15)
    parallel_api_test(env, num_cycles=20)
    obs, _ = env.reset(seed=3)
    assert sorted(obs) == sorted(env.possible_agents) and len(obs) == 10
    assert obs["robot_0"].shape == env.observation_space("robot_0").shape
    done = False
    while not done:
        _, _rewards, terms, truncs, infos = env.step({a: np.array([1.0, 0.0], np.float32) for a in env.agents})
        done = all(truncs.values())
    assert not any(terms.values()) and env.agents == []
    assert {"success_rate", "collisions_per_episode", "episode_return"} <= set(infos["robot_0"])


def test_seeded_episodes_repeat_exactly() -> None:
    from stafpipe.marl_env import parallel_env

    def run(seed: int) -> list[float]:
        env = parallel_env(scenario="bridge", episode_steps=12)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        out = [float(obs["robot_3"].sum())]
        while env.agents:
            obs, rewards, *_ = env.step({a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents})
            out += [float(sum(rewards.values()))] + [float(o.sum()) for o in obs.values()]
        return out

    assert run(4) == run(4) and run(4) != run(5)


@pytest.mark.parametrize("method", ["dgnn", "staf_planned"])
def test_batched_env_rewards_are_the_trainers(method) -> None:
    policy_cfg = PolicyConfig(hidden=16)
    policy = build_policy(method, policy_cfg)
    tc = TrainPPOConfig(method=method, worlds=3, episode_steps=25, policy=policy_cfg)
    corridor = load_named_scenario("corridor")
    drawn = [(corridor, *path_and_width(corridor))] * 3
    worlds = Worlds([corridor] * 3, SensingConfig(), WorldConfig())
    obs = worlds.reset([7, 8, 9])
    adapter = adapter_class(method)(policy_cfg, RewardConfig(), None, 2.0)
    adapter.begin(teams_of(drawn, worlds))
    rollout, stats = collect(policy, adapter, worlds, obs, tc, 0.3, deterministic=True)

    env = BatchedTeamEnv("corridor", worlds=3, method=method, episode_steps=25, policy=policy_cfg)
    feats = env.reset(7)
    rewards = []
    done, info = False, {}
    while not done:
        with torch.no_grad():
            act = policy.act(*(torch.from_numpy(feats[k]) for k in ("own", "edge", "mask"))).numpy()
        feats, reward, done, info = env.step(act)
        rewards.append(reward)
    assert np.allclose(np.stack(rewards), rollout.rewards.numpy(), atol=1e-5)
    assert np.abs(np.stack(rewards)).max() > 0.01  # robots moved and were rewarded for it
    assert (
        info["success_rate"] == stats["success_rate"]
        and info["collisions_per_episode"] == stats["collisions_per_episode"]
    )


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_torchrl_drives_the_environment_through_its_pettingzoo_wrapper() -> None:
    pytest.importorskip("torchrl")  # the `torchrl` extra: a third-party library stepping our environment
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    from stafpipe.marl_env import parallel_env

    env = PettingZooWrapper(parallel_env(scenario="corridor", episode_steps=100), use_mask=False)
    rollout = env.rollout(300, break_when_any_done=False)  # random actions, three episodes (reset on truncation)
    group = rollout["agents"] if "agents" in rollout.keys() else rollout[next(iter(env.group_map))]  # noqa: SIM118 (a TensorDict)
    assert group["observation"].shape[:2] == (300, 10) and group["action"].shape[-1] == 2
    assert int(rollout["next", "truncated"].sum()) == 3
