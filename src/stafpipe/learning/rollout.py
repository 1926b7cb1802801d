"""One PPO rollout: B worlds of the harness, one episode each, every robot's transition a sample (parameter sharing)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from stafpipe.controllers.staf_plan import StafPlan
from stafpipe.learning.config import PolicyConfig, RewardConfig, TrainPPOConfig
from stafpipe.learning.features import Features, features, guide_targets, staf_features
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
    a = np.clip(actions, -1.0, 1.0) * max_speed
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([c * a[..., 0] - s * a[..., 1], s * a[..., 0] + c * a[..., 1]], axis=-1)


def contact_penalties(worlds: Worlds, obs: Observation, rc: RewardConfig) -> np.ndarray:
    """(B, n) collision and wall-contact penalties of this step (DGNN's -1.5 and -0.25 per contact)."""
    gap = np.linalg.norm(worlds.pos[:, :, None] - worlds.pos[:, None], axis=-1) - 2 * worlds.robot.radius
    idx = np.arange(worlds.n)
    gap[:, idx, idx] = np.inf
    robot_hits = (gap < rc.contact_tolerance).sum(-1)
    wall = obs.obstacle_distance < rc.contact_tolerance
    return rc.robot_collision * robot_hits + rc.wall_contact * wall


def targets(worlds: Worlds, paths: list[np.ndarray] | None, pc: PolicyConfig) -> np.ndarray | None:
    """(B, n, 2) guide targets of every world (None: the robots' own goals)."""
    if pc.guide != "path" or paths is None:
        return None
    return np.stack([guide_targets(worlds.pos[w], worlds.goal[w], paths[w], pc.lookahead, pc.release)
                     for w in range(worlds.size)])


def staf_penalties(worlds: Worlds, obs: Observation, plans: list[StafPlan], rc: RewardConfig) -> np.ndarray:
    """(B, n) STAF's formation and proximity terms of this step. R^adp (Sec. 3) over the robot's subteam mates,
    -lambda |d_ij - p_ij| - (1 - lambda) q_ij with d_ij from the plan's (adapted) formation, averaged over the mates
    so that subteams of any size weigh alike; proximity: linear in how far a gap is below `safe_distance`."""
    expected = np.stack([p.expected for p in plans])
    same = np.stack([p.same for p in plans]) & ~np.eye(worlds.n, dtype=bool)
    dist = np.linalg.norm(worlds.pos[:, :, None] - worlds.pos[:, None], axis=-1)
    q = np.linalg.norm(worlds.vel[:, :, None] - worlds.vel[:, None], axis=-1)
    pair = -rc.adp_lambda * np.abs(expected - dist) - (1.0 - rc.adp_lambda) * q
    adp = (pair * same).sum(-1) / np.maximum(same.sum(-1), 1)
    gap = dist - 2 * worlds.robot.radius + np.eye(worlds.n) * 1e9
    near = np.clip(1.0 - gap / rc.safe_distance, 0.0, 1.0).sum(-1)
    near += np.clip(1.0 - obs.obstacle_distance / rc.safe_distance, 0.0, 1.0)
    return rc.formation * adp - rc.proximity * near


def staf_inputs(obs: Observation, plans: list[StafPlan], pc: PolicyConfig, sensing_radius: float,
                dt: float) -> tuple[Features, np.ndarray]:
    """Advance every world's plan by one step; the policy's features and the targets (B, n, 2)."""
    target = np.stack([p.step(obs.position[w], dt) for w, p in enumerate(plans)])
    same = np.stack([p.same for p in plans])
    return staf_features(obs, target, same, pc.goal_clip, sensing_radius), target


def collect(policy: torch.nn.Module, worlds: Worlds, obs: Observation, tc: TrainPPOConfig, tolerance: float,
            sensing_radius: float, paths: list[np.ndarray] | None = None, deterministic: bool = False,
            plans: list[StafPlan] | None = None) -> tuple[Rollout, dict[str, float]]:
    """Run `tc.episode_steps` steps in every world with actions sampled from the policy (its mean if `deterministic`,
    as `method=dgnn` evaluates it); `paths` are the worlds' team-centre shortest paths (for `policy.guide=path`);
    `plans` (method=staf) are the worlds' STAF plans, which give the targets and the formation term."""
    rc, clip = tc.reward, tc.policy.goal_clip
    dt = worlds.cfg.control_dt
    buf: dict[str, list] = {k: [] for k in ("own", "edge", "mask", "actions", "logprobs", "values", "rewards")}
    dist = np.linalg.norm(worlds.goal - worlds.pos, axis=-1)
    reached = dist <= tolerance
    hits = 0
    for _ in range(tc.episode_steps):
        if plans is None:
            f, target = features(obs, clip, sensing_radius, targets(worlds, paths, tc.policy)), worlds.goal
        else:
            f, target = staf_inputs(obs, plans, tc.policy, sensing_radius, dt)
        before = np.linalg.norm(target - worlds.pos, axis=-1)
        own, edge, mask = torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask)
        with torch.no_grad():
            mean, value = policy(own, edge, mask)
            dist_a = policy.distribution(mean)
            action = mean if deterministic else dist_a.sample()
            logprob = dist_a.log_prob(action).sum(-1)
        obs, events = worlds.step(commands(action.numpy(), worlds.heading, worlds.robot.max_speed))
        hits += sum(len(e) for e in events)
        goal = worlds.goal if plans is None else np.stack([p.goal for p in plans])  # STAF reassigns slots at regroup
        new_dist = np.linalg.norm(goal - worlds.pos, axis=-1)
        now_reached = new_dist <= tolerance
        progress = dist - new_dist if plans is None else before - np.linalg.norm(target - worlds.pos, axis=-1)
        reward = rc.progress * progress + rc.goal * (now_reached & ~reached) + contact_penalties(worlds, obs, rc)
        if plans is not None:
            reward = reward + staf_penalties(worlds, obs, plans, rc)
        dist, reached = new_dist, reached | now_reached
        for key, v in (("own", own), ("edge", edge), ("mask", mask), ("actions", action), ("logprobs", logprob),
                       ("values", value), ("rewards", torch.from_numpy(reward.astype(np.float32)))):
            buf[key].append(v)
    if plans is None:
        f = features(obs, clip, sensing_radius, targets(worlds, paths, tc.policy))
    else:
        f = staf_inputs(obs, plans, tc.policy, sensing_radius, 0.0)[0]
    with torch.no_grad():
        _, last_value = policy(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
    rollout = Rollout(**{k: torch.stack(v) for k, v in buf.items()}, last_value=last_value)
    at_goal = dist <= tolerance
    stats = {
        "success_rate": float((at_goal & ~worlds.collided).mean()),  # the harness' SR: at goal, never collided
        "at_goal": float(at_goal.mean()),
        "reached_once": float(reached.mean()),
        "collisions_per_episode": hits / worlds.size,
        "episode_return": float(rollout.rewards.sum(0).mean()),
    }
    return rollout, stats


def gae(rewards: torch.Tensor, values: torch.Tensor, last_value: torch.Tensor, gamma: float,
        lam: float) -> tuple[torch.Tensor, torch.Tensor]:
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
