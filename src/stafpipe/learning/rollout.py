"""One PPO rollout: B worlds of the harness, one episode each, every robot's transition a sample (parameter sharing)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from stafpipe.learning.adapters import Adapter
from stafpipe.learning.config import RewardConfig, TrainPPOConfig
from stafpipe.learning.features import stack_xy
from stafpipe.learning.policy_net import PolicyNet
from stafpipe.metrics import RouteProgress
from stafpipe.sensing import Observation
from stafpipe.world import Worlds


class Rollout(NamedTuple):
    """Buffers shaped (T, B, n, ...) as in CleanRL, plus the bootstrap value after the last step."""

    own: torch.Tensor
    edge: torch.Tensor
    mask: torch.Tensor
    actions: torch.Tensor
    logprobs: torch.Tensor
    values: torch.Tensor
    rewards: torch.Tensor
    last_value: torch.Tensor
    """(B, n): V(s_T), the episode is truncated there."""


def commands(actions: np.ndarray, heading: np.ndarray, max_speed: float) -> np.ndarray:
    """Policy outputs (robot frame, clipped to [-1, 1]) -> world-frame velocity commands (m/s)."""
    a = np.minimum(np.maximum(actions, -1.0), 1.0) * max_speed  # np.clip's values, without its call overhead
    c, s = np.cos(heading), np.sin(heading)
    return stack_xy(c * a[..., 0] - s * a[..., 1], s * a[..., 0] + c * a[..., 1])


def contact_penalties(worlds: Worlds, obs: Observation, rc: RewardConfig) -> np.ndarray:
    """(B, n) collision and wall-contact penalties of this step (DGNN's -1.5 and -0.25 per contact)."""
    gap = np.linalg.norm(worlds.pos[:, :, None] - worlds.pos[:, None], axis=-1) - 2 * worlds.robot.radius
    idx = np.arange(worlds.n)
    gap[:, idx, idx] = np.inf
    robot_hits = (gap < rc.contact_tolerance).sum(-1)
    wall = obs.obstacle_distance < rc.contact_tolerance
    return rc.robot_collision * robot_hits + rc.wall_contact * wall


def world_routes(worlds: Worlds) -> RouteProgress:
    """The routes (`reference_path`) of the worlds' scenarios, none passed yet."""
    return RouteProgress([sc.spec.reference_path for sc in worlds.scenarios])


def step_reward(
    adapter: Adapter,
    worlds: Worlds,
    obs: Observation,
    aim: np.ndarray,
    before: np.ndarray,
    reached: np.ndarray,
    tolerance: float,
    rc: RewardConfig,
    route: RouteProgress | None = None,
) -> tuple[np.ndarray, ...]:
    """(B, n) reward of the step just taken, each robot's distance to its goal slot and whether it has reached it:
    progress towards the adapter's aim (from `before`), the one-off arrival bonus, contacts and the method's own
    terms. The trainer and the multi-agent environment (marl_env.py) both reward through this. With `route` (the
    worlds' reference paths), a goal slot counts once the team has passed its route, as in SR (docs/metrics.md)."""
    new_dist = np.linalg.norm(adapter.goals() - worlds.pos, axis=-1)
    now_reached = new_dist <= tolerance
    if route is not None:
        now_reached &= route.update(worlds.pos)[:, None]
    progress = before - np.linalg.norm(aim - worlds.pos, axis=-1)
    reward = rc.progress * progress + rc.goal * (now_reached & ~reached) + contact_penalties(worlds, obs, rc)
    reward = reward + adapter.reward(worlds.pos, worlds.vel, obs)
    return reward, new_dist, reached | now_reached


def episode_stats(
    worlds: Worlds,
    dist: np.ndarray,
    reached: np.ndarray,
    tolerance: float,
    hits: int,
    returns: np.ndarray | torch.Tensor,
) -> dict[str, float]:
    """The trainer's end-of-episode metrics of B worlds; `returns` (B, n) the robots' summed rewards."""
    at_goal = dist <= tolerance
    return {
        "success_rate": float((at_goal & ~worlds.collided).mean()),  # the harness' SR: at goal, never collided
        "at_goal": float(at_goal.mean()),
        "reached_once": float(reached.mean()),
        "collisions_per_episode": hits / worlds.size,
        "episode_return": float(returns.mean()),
    }


def collect(
    policy: PolicyNet,
    adapter: Adapter,
    worlds: Worlds,
    obs: Observation,
    tc: TrainPPOConfig,
    tolerance: float,
    deterministic: bool = False,
) -> tuple[Rollout, dict[str, float]]:
    """Run `tc.episode_steps` steps in every world with actions sampled from the policy (its mean if `deterministic`,
    as evaluation acts); the method's `adapter` (begun on these worlds' teams) gives the features, the point each
    robot's progress is measured to, its goal slot and the method's own reward terms."""
    rc = tc.reward
    dt = worlds.cfg.control_dt
    buf: dict[str, list] = {k: [] for k in ("own", "edge", "mask", "actions", "logprobs", "values", "rewards")}
    dist = np.linalg.norm(adapter.goals() - worlds.pos, axis=-1)
    route = world_routes(worlds)
    reached = (dist <= tolerance) & route.update(worlds.pos)[:, None]
    hits = 0
    for _ in range(tc.episode_steps):
        f, aim, _ = adapter.step(obs, dt)
        before = np.linalg.norm(aim - worlds.pos, axis=-1)
        own, edge, mask = torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask)
        with torch.no_grad():
            mean, value = policy(own, edge, mask)
            dist_a = policy.distribution(mean)
            action = mean if deterministic else dist_a.sample()
            logprob = dist_a.log_prob(action).sum(-1)
        obs, events = worlds.step(commands(action.numpy(), worlds.heading, worlds.robot.max_speed))
        hits += sum(len(e) for e in events)
        reward, dist, reached = step_reward(adapter, worlds, obs, aim, before, reached, tolerance, rc, route)
        for key, v in (
            ("own", own),
            ("edge", edge),
            ("mask", mask),
            ("actions", action),
            ("logprobs", logprob),
            ("values", value),
            ("rewards", torch.from_numpy(reward.astype(np.float32))),
        ):
            buf[key].append(v)
    f = adapter.step(obs, 0.0).features
    with torch.no_grad():
        _, last_value = policy(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
    rollout = Rollout(**{k: torch.stack(v) for k, v in buf.items()}, last_value=last_value)
    return rollout, episode_stats(worlds, dist, reached, tolerance, hits, rollout.rewards.sum(0))


def gae(
    rewards: torch.Tensor, values: torch.Tensor, last_value: torch.Tensor, gamma: float, lam: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalized advantage estimation over (T, ...) buffers of one truncated episode (no terminal inside it):
    delta_t = r_t + gamma V(s_{t+1}) - V(s_t); A_t = delta_t + gamma lam A_{t+1}. Returns (advantages, returns)."""
    adv = torch.zeros_like(rewards)
    next_adv = torch.zeros_like(last_value)
    next_value = last_value
    for t in reversed(range(len(rewards))):
        delta = rewards[t] + gamma * next_value - values[t]
        next_adv = delta + gamma * lam * next_adv
        adv[t] = next_adv
        next_value = values[t]
    return adv, adv + values
