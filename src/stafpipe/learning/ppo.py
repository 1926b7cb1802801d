"""PPO (STAF Appendix B.1, Eq. (2); Schulman et al. [67]) for robot teams, read top to bottom as in CleanRL:
collect a rollout from B batched worlds, compute GAE, update with the clipped objective, log, checkpoint.

Parameter sharing: one policy for every robot, each robot's transition one sample of Eq. (2)'s sum over robots; the
critic head also sees the team's mean embedding (centralized critic). Every iteration resets its worlds with seeds
drawn from (seed, iteration), so the full state after an iteration (weights, optimiser, torch RNG, history) is an exact
resume point: a resumed run ends with the same weights as an uninterrupted one.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from stafpipe.learning.config import TrainPPOConfig
from stafpipe.controllers.staf_plan import StafPlan
from stafpipe.learning.checkpoint import build_policy
from stafpipe.learning.rollout import Rollout, collect, gae
from stafpipe.scenario import Scenario
from stafpipe.sensing import SensingConfig
from stafpipe.torch_io import save_payload
from stafpipe.world import WorldConfig, Worlds

log = logging.getLogger(__name__)
STATE_FILE = "ppo_state.pt"
EVAL_SEED = 10_000_019  # evaluation episodes use seeds EVAL_SEED + world, never a training draw


def update(policy: torch.nn.Module, opt: torch.optim.Optimizer, ro: Rollout, adv: torch.Tensor, ret: torch.Tensor,
           tc: TrainPPOConfig, gen: torch.Generator) -> dict[str, float]:
    """`tc.epochs` passes of minibatch updates over world-steps (a sample keeps its world's n robots together)."""
    t, b = ro.rewards.shape[:2]
    flat = lambda x: x.reshape(t * b, *x.shape[2:])  # noqa: E731
    b_own, b_edge, b_mask, b_act = flat(ro.own), flat(ro.edge), flat(ro.mask), flat(ro.actions)
    b_logp, b_adv, b_ret = flat(ro.logprobs), flat(adv), flat(ret)
    size = t * b // tc.minibatches
    out = {"losses/policy": 0.0, "losses/value": 0.0, "losses/entropy": 0.0, "losses/approx_kl": 0.0,
           "losses/clipfrac": 0.0}
    count = 0
    for _ in range(tc.epochs):
        order = torch.randperm(t * b, generator=gen)
        for k in range(tc.minibatches):
            mb = order[k * size : (k + 1) * size]
            mean, value = policy(b_own[mb], b_edge[mb], b_mask[mb])
            dist = policy.distribution(mean)
            logp = dist.log_prob(b_act[mb]).sum(-1)
            ratio = (logp - b_logp[mb]).exp()
            mb_adv = (b_adv[mb] - b_adv[mb].mean()) / (b_adv[mb].std() + 1e-8)
            # Eq. (2): min(ratio A, clip(ratio, 1 - delta, 1 + delta) A), as a loss to minimise
            pg_loss = torch.max(-mb_adv * ratio, -mb_adv * ratio.clamp(1 - tc.clip, 1 + tc.clip)).mean()
            v_loss = 0.5 * ((value - b_ret[mb]) ** 2).mean()
            entropy = dist.entropy().sum(-1).mean()
            loss = pg_loss + tc.vf_coef * v_loss - tc.ent_coef * entropy
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), tc.max_grad_norm)
            opt.step()
            with torch.no_grad():
                out["losses/approx_kl"] += float(((ratio - 1) - (logp - b_logp[mb])).mean())
                out["losses/clipfrac"] += float(((ratio - 1).abs() > tc.clip).float().mean())
            out["losses/policy"] += float(pg_loss.detach())
            out["losses/value"] += float(v_loss.detach())
            out["losses/entropy"] += float(entropy.detach())
            count += 1
    return {k: v / count for k, v in out.items()}


Drawn = tuple[Scenario, np.ndarray, float]
"""A world's scenario, its team-centre shortest path and its narrowest passage width."""


def make_plans(tc: TrainPPOConfig, drawn: list[Drawn], worlds: Worlds, divide: Callable | None) -> list[StafPlan] | None:
    """method=staf: a fresh STAF plan per world (after `worlds.reset`, which sets the goals); None for dgnn."""
    if divide is None:
        return None
    return [StafPlan(tc.plan, sc, sc.template(), worlds.goal[w], path, eta, divide)
            for w, (sc, path, eta) in enumerate(drawn)]


def train_ppo(tc: TrainPPOConfig, draw_scenarios: Callable[[np.random.Generator, int], list[Drawn]],
              world_cfg: WorldConfig, sensing: SensingConfig, tolerance: float, seed: int, out_dir: Path,
              config_hash: str, resume_from: Path | None, on_iteration: Callable[[list[dict[str, float]]], None]
              ) -> tuple[torch.nn.Module, list[dict[str, float]]]:
    """Train; after every `checkpoint_every` iterations (and the last) `out_dir/ppo_state.pt` holds the whole state."""
    torch.set_num_threads(tc.threads)
    torch.manual_seed(seed)
    policy = build_policy(tc.method, tc.policy)
    divide = None
    if tc.method == "staf":  # App. B.1: the high level is trained first and fixed while PPO trains phi and psi
        from stafpipe.highlevel.infer import divider

        divide = divider(tc.plan.high_checkpoint)
    opt = torch.optim.Adam(policy.parameters(), lr=tc.lr, eps=1e-5)
    gen = torch.Generator().manual_seed(seed)
    history: list[dict[str, float]] = []
    start = 0
    if resume_from is not None:
        state = torch.load(resume_from, map_location="cpu", weights_only=True)
        policy.load_state_dict(state["policy"])
        opt.load_state_dict(state["optimizer"])
        torch.set_rng_state(state["torch_rng"])
        gen.set_state(state["minibatch_rng"])
        history, start = state["history"], int(state["iteration"])
        log.info("resumed from iteration %d of %s", start, resume_from)
    bar = tqdm(range(start, tc.iterations), desc="train-ppo", unit="it", initial=start, total=tc.iterations, disable=None)
    for it in bar:
        began = time.perf_counter()
        rng = np.random.default_rng([seed, it])
        drawn = draw_scenarios(rng, tc.worlds)  # (scenario, its team-centre shortest path, eta) per world
        worlds = Worlds([d[0] for d in drawn], sensing, world_cfg)
        obs = worlds.reset([int(x) for x in rng.integers(0, 2**31, tc.worlds)])
        ro, stats = collect(policy, worlds, obs, tc, tolerance, sensing.radius, [d[1] for d in drawn],
                            plans=make_plans(tc, drawn, worlds, divide))
        collected = time.perf_counter()
        adv, ret = gae(ro.rewards, ro.values, ro.last_value, tc.gamma, tc.gae_lambda)
        losses = update(policy, opt, ro, adv, ret, tc, gen)
        done = time.perf_counter()
        samples = ro.rewards.numel()
        row = {"iteration": it + 1, "robot_steps": float((it + 1) * samples),
               **{f"charts/{k}": v for k, v in stats.items()}, **losses,
               "charts/fps": samples / (done - began), "charts/rollout_fps": samples / (collected - began),
               "charts/update_seconds": done - collected, "charts/log_std": float(policy.log_std.detach().mean())}
        if tc.eval_every and ((it + 1) % tc.eval_every == 0 or it + 1 == tc.iterations):
            worlds = Worlds([d[0] for d in drawn], sensing, world_cfg)  # same scenarios, fixed evaluation seeds
            obs = worlds.reset([EVAL_SEED + w for w in range(tc.worlds)])
            _, ev = collect(policy, worlds, obs, tc, tolerance, sensing.radius, [d[1] for d in drawn],
                            deterministic=True, plans=make_plans(tc, drawn, worlds, divide))
            row.update({f"eval/{k}": v for k, v in ev.items()})
        history.append(row)
        bar.set_postfix(sr=f"{stats['success_rate']:.2f}", ret=f"{stats['episode_return']:.1f}")
        if (it + 1) % tc.checkpoint_every == 0 or it + 1 == tc.iterations:
            save_payload(out_dir / STATE_FILE, {"config_hash": config_hash, "iteration": it + 1,
                                              "policy": policy.state_dict(), "optimizer": opt.state_dict(),
                                              "torch_rng": torch.get_rng_state(), "minibatch_rng": gen.get_state(),
                                              "history": history})
        on_iteration(history)
    return policy, history
