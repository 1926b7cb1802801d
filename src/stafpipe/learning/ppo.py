"""PPO (STAF Appendix B.1, Eq. (2); Schulman et al. [67]) for robot teams, read top to bottom as in CleanRL:
collect a rollout from B batched worlds, compute GAE, update with the clipped objective, log, checkpoint.

Parameter sharing: one policy for every robot, each robot's transition one sample of Eq. (2)'s sum over robots; the
critic head also sees the team's mean embedding (centralized critic). Every iteration resets its worlds with seeds
drawn from (seed, iteration), so the full state after an iteration (weights, optimiser, torch RNG, history) is an exact
resume point: a resumed run ends with the same weights as an uninterrupted one.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from stafpipe.controllers.base import TeamInfo
from stafpipe.errors import StafpipeError
from stafpipe.learning.adapters import Adapter
from stafpipe.learning.config import TrainPPOConfig
from stafpipe.learning.distributed import ALONE, Workers
from stafpipe.learning.features import Features
from stafpipe.learning.policy_net import PolicyNet
from stafpipe.learning.rollout import Rollout, collect, commands, gae
from stafpipe.learning.teachers import near_neighbour_copy, near_wall_copy, teacher_actions
from stafpipe.progress import progress
from stafpipe.registry import adapter_class
from stafpipe.scenario import Scenario
from stafpipe.sensing import Observation, SensingConfig
from stafpipe.torch_io import save_payload, training_device
from stafpipe.world import WorldConfig, Worlds

log = logging.getLogger(__name__)
STATE_FILE = "ppo_state.pt"
EVAL_SEED = 10_000_019  # evaluation episodes use seeds EVAL_SEED + world, never a training draw
VALIDATION_SEED = 20_000_033  # held-out validation episodes: VALIDATION_SEED + world


def _on(ro: Rollout, device: torch.device) -> Rollout:
    return Rollout(*(x.to(device) for x in ro))


def update(
    policy: PolicyNet,
    opt: torch.optim.Optimizer,
    ro: Rollout,
    adv: torch.Tensor,
    ret: torch.Tensor,
    tc: TrainPPOConfig,
    gen: torch.Generator,
    device: torch.device | None = None,
    workers: Workers = ALONE,
) -> dict[str, float]:
    """`tc.epochs` passes of minibatch updates over world-steps (a sample keeps its world's n robots together). On
    `device` (train_ppo.device) the network, its optimizer state and the samples move there for the update; the
    network comes back to the CPU for the next rollout. With `workers`, each worker's minibatches are of its own
    samples and every step uses the gradient averaged over the workers (DD-PPO, learning/distributed.py)."""
    if device is not None and device.type != "cpu":
        policy.to(device)  # in place: the optimizer keeps the same parameters
        for state in opt.state.values():
            for name, value in state.items():
                if torch.is_tensor(value):
                    state[name] = value.to(device)
        try:
            return update(policy, opt, _on(ro, device), adv.to(device), ret.to(device), tc, gen, None, workers)
        finally:
            policy.cpu()
    t, b = ro.rewards.shape[:2]
    flat = lambda x: x.reshape(t * b, *x.shape[2:])  # noqa: E731
    b_own, b_edge, b_mask, b_act = flat(ro.own), flat(ro.edge), flat(ro.mask), flat(ro.actions)
    b_logp, b_adv, b_ret = flat(ro.logprobs), flat(adv), flat(ret)
    size = t * b // tc.minibatches
    # each minibatch's statistics stay on the device until the end: reading one (float()) waits for the device, and
    # on a GPU that wait at every minibatch was most of the update's excess over the network's own cost
    # (benchmarks/ppo_throughput.py)
    stats: list[torch.Tensor] = []
    exchange = 0.0  # seconds in the workers' gradient all-reduce, waiting for the slowest included
    for _ in range(tc.epochs):
        order = torch.randperm(t * b, generator=gen).to(b_own.device)
        for k in range(tc.minibatches):
            mb = order[k * size : (k + 1) * size]
            mean, value = policy(b_own[mb], b_edge[mb], b_mask[mb])
            dist = policy.distribution(mean, validate=False)
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
            began = time.perf_counter()
            workers.average_gradients(policy.parameters())
            exchange += time.perf_counter() - began
            torch.nn.utils.clip_grad_norm_(policy.parameters(), tc.max_grad_norm)
            opt.step()
            with torch.no_grad():
                kl = ((ratio - 1) - (logp - b_logp[mb])).mean()
                clipfrac = ((ratio - 1).abs() > tc.clip).float().mean()
                stats.append(torch.stack([pg_loss, v_loss, entropy, kl, clipfrac]).detach())
    rows = torch.stack(stats).cpu().tolist()  # one read; summed in order, as Python floats, minibatch by minibatch
    names = ("losses/policy", "losses/value", "losses/entropy", "losses/approx_kl", "losses/clipfrac")
    diverged = not all(math.isfinite(v) for row in rows for v in row)
    if workers.total([float(diverged)], "max")[0]:  # every worker stops, not one while the others wait for it
        raise StafpipeError(
            "train_ppo: the PPO update's losses are not finite (NaN or inf): training diverged; a lower "
            "train_ppo.lr or train_ppo.max_grad_norm may help"
        )
    losses = workers.mean({name: sum((row[c] for row in rows), 0.0) / len(rows) for c, name in enumerate(names)})
    if workers.size > 1:
        losses["charts/exchange_seconds"] = workers.total([exchange], "max")[0]
    return losses


Drawn = tuple[Scenario, np.ndarray, float]
"""A world's scenario, its team-centre shortest path (TeamInfo.path) and its narrowest passage width."""


def teams_of(drawn: list[Drawn], worlds: Worlds) -> list[TeamInfo]:
    """What each world's controller knows at the start of an episode (after `worlds.reset`), as in `eval`."""
    return [
        TeamInfo(sc, worlds.pos[w].copy(), worlds.goal[w].copy(), sc.template(), path, eta)
        for w, (sc, path, eta) in enumerate(drawn)
    ]


def _teacher_samples(
    policy: PolicyNet | None,
    adapter: Adapter,
    drawn: list[Drawn],
    world_cfg: WorldConfig,
    sensing: SensingConfig,
    tc: TrainPPOConfig,
    rng: np.random.Generator,
) -> tuple[torch.Tensor, ...]:
    """One batch of episodes with the teacher's action as the label of every state: driven by the teacher itself
    (`policy` None) or by the network's mean action (DAgger), with Gaussian action noise."""
    im = tc.imitation
    worlds = Worlds([d[0] for d in drawn], sensing, world_cfg)
    obs = worlds.reset([int(x) for x in rng.integers(0, 2**31, len(drawn))])
    adapter.begin(teams_of(drawn, worlds), privileged=im.privileged)
    own: list[torch.Tensor] = []
    edge: list[torch.Tensor] = []
    mask: list[torch.Tensor] = []
    target: list[torch.Tensor] = []
    weight: list[torch.Tensor] = []
    radius, top, robot_drive = worlds.robot.radius, worlds.robot.max_speed, worlds.robot.drive

    def labelled(f: Features, seen: Observation, to_aim: np.ndarray) -> np.ndarray:
        """Store one step's samples (features `f` of observation `seen`) with the teacher's actions as labels."""
        act = teacher_actions(im.teacher, to_aim, seen, radius, top, im.gain, robot_drive, im.stop_gap)
        for store, x in ((own, f.own), (edge, f.edge), (mask, f.mask)):
            store.append(torch.from_numpy(x))
        target.append(torch.from_numpy(act.astype(np.float32)))
        braking = np.zeros(act.shape[:-1], dtype=bool)
        if im.near_weight != 1:  # where the teacher brakes for a neighbour or a wall the sample weighs more
            free = teacher_actions("proportional", to_aim, seen, radius, top, im.gain, robot_drive)
            braking = np.abs(act - free).sum(-1) > 1e-6
        weight.append(torch.from_numpy(np.where(braking, im.near_weight, 1.0)).float())
        return act

    for _ in range(tc.episode_steps):
        f = adapter.step(obs, world_cfg.control_dt).features
        to_aim = adapter.teacher_aim() - obs.position
        drive = labelled(f, obs, to_aim)
        if policy is not None:
            with torch.no_grad():
                drive = policy.act(*(torch.from_numpy(x) for x in (f.own, f.edge, f.mask))).numpy().astype(float)
        for fraction, copy_of in ((im.wall_copies, near_wall_copy), (im.neighbour_copies, near_neighbour_copy)):
            if fraction > 0 and rng.random() < fraction:  # no draw without copies: old recipes unchanged
                near = copy_of(obs, radius, rng)
                labelled(adapter.features(near), near, to_aim)
        obs, _ = worlds.step(
            commands(drive + rng.normal(0.0, im.noise, drive.shape), worlds.heading, worlds.robot.max_speed)
        )
    return tuple(torch.cat(x) for x in (own, edge, mask, target, weight))


DIRECTION_FLOOR = 1e-2
"""Length below which the direction term (`imitation.direction_weight`) sees the network's action as this long: a
bounded gradient for an action near zero (its cosine shrinks with it). A teacher's action shorter than 1e-6 has no
direction and adds no term."""


def imitation_loss(
    act: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, near_weight: float, direction_weight: float
) -> torch.Tensor:
    """The warm start's loss over (samples, robots, 2) actions: squared error to the teacher's action, plus
    `direction_weight` x (1 - cos) of the angle between them where the teacher's action has a direction, averaged
    over robots with `weight` (where `near_weight` != 1)."""
    err = ((act - target) ** 2).sum(-1)
    if direction_weight > 0:
        length = torch.linalg.vector_norm(target, dim=-1)
        cos = (act * target).sum(-1) / (
            torch.linalg.vector_norm(act, dim=-1).clamp_min(DIRECTION_FLOOR) * length.clamp_min(1e-6)
        )
        err = err + direction_weight * torch.where(length > 1e-6, 1 - cos, torch.zeros_like(cos))
    return err.mean() if near_weight == 1 else (err * weight).sum() / weight.sum()


def imitate(
    policy: PolicyNet,
    adapter: Adapter,
    draw: Callable[[np.random.Generator, int], list[Drawn]],
    world_cfg: WorldConfig,
    sensing: SensingConfig,
    tc: TrainPPOConfig,
    seed: int,
) -> dict[str, float]:
    """Warm start (`train_ppo.imitation.epochs` > 0): the network learns to imitate a hand-made low level (the
    teacher, learning/teachers.py) by supervised regression of the action mean, first on states the teacher visits,
    then (`imitation.dagger` rounds, DAgger: Ross, Gordon and Bagnell, AISTATS 2011) on states the network itself
    visits, labelled by the teacher, all samples kept. With `imitation.privileged` the teacher may see more than the
    network (`Adapter.teacher_aim`: for STAF with `plan.adapt=nominal`, the targets of the geometrically adapted plan,
    while the network sees the nominal ones and must infer the adaptation from what it senses). The teacher is then
    gone: PPO trains the network alone, a_i = psi(f_i) as printed (docs/staf_planned.md)."""
    im = tc.imitation
    rng = np.random.default_rng([seed, 7])
    opt = torch.optim.Adam(policy.parameters(), lr=im.lr)
    gen = torch.Generator().manual_seed(seed)
    sets: list[tuple[torch.Tensor, ...]] = []  # one per batch of episodes: its worlds share the team size
    loss = torch.zeros(())
    for round_ in progress(range(1 + im.dagger), desc="train-ppo: imitation", unit="round"):
        driver = policy if round_ > 0 or tc.init_from else None  # a loaded network drives from the first round
        sets += [
            _teacher_samples(driver, adapter, draw(rng, tc.worlds), world_cfg, sensing, tc, rng)
            for _ in range(im.rollouts)
        ]
        for _ in range(im.epochs):
            for k in torch.randperm(len(sets), generator=gen).tolist():
                b_own, b_edge, b_mask, b_target, b_weight = sets[k]
                order = torch.randperm(len(b_own), generator=gen)
                for start in range(0, len(order), im.batch):
                    mb = order[start : start + im.batch]
                    act = policy.act(b_own[mb], b_edge[mb], b_mask[mb])
                    loss = imitation_loss(act, b_target[mb], b_weight[mb], im.near_weight, im.direction_weight)
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
        log.info(
            "imitation round %d (%s teacher): %d batches, loss %.4f",
            round_,
            im.teacher,
            len(sets),
            float(loss.detach()),
        )
    samples = sum(x[0].shape[0] * x[0].shape[1] for x in sets)
    return {"imitation/loss": float(loss.detach()), "imitation/samples": float(samples)}


def train_ppo(
    tc: TrainPPOConfig,
    draw_scenarios: Callable[[np.random.Generator, int], list[Drawn]],
    world_cfg: WorldConfig,
    sensing: SensingConfig,
    tolerance: float,
    seed: int,
    out_dir: Path,
    config_hash: str,
    resume_from: Path | None,
    on_iteration: Callable[[list[dict[str, float]]], None],
    validation: list[list[Drawn]] | None = None,
    workers: Workers = ALONE,
) -> tuple[PolicyNet, list[dict[str, float]]]:
    """Train; after every `checkpoint_every` iterations (and the last) `out_dir/ppo_state.pt` holds the whole state.
    With `validation` (batches of held-out worlds), the returned network is the one of `best_iteration`.

    With `workers` (DD-PPO, learning/distributed.py) every worker draws the same worlds and steps its share of
    them, the update averages their gradients, and the curves' rates and losses are averaged over them (robot-steps
    summed, seconds the slowest worker's), so every worker ends with the same weights and the same history; the main
    worker alone runs the warm start, writes the state and calls `on_iteration`."""
    torch.set_num_threads(tc.threads)
    device = training_device(tc.device, "train_ppo.device")
    torch.manual_seed(seed)
    kind = adapter_class(tc.method)
    adapter = kind(tc.policy, tc.reward, getattr(tc, kind.plan_key), sensing.radius)
    policy = adapter.network(tc.policy)
    if tc.init_from and resume_from is None:
        policy.load_state_dict(initial_weights(tc).state_dict())
    if not workers.main:  # the same initial weights as the main worker's, then action noise of its own
        torch.manual_seed(workers.seed(seed))
    history: list[dict[str, float]] = []
    start = 0
    warm: dict[str, float] = {}
    best: dict[str, Any] = {}  # the weights of the best validation iteration so far
    opt = torch.optim.Adam(policy.parameters(), lr=tc.lr, eps=1e-5)
    gen = torch.Generator().manual_seed(workers.seed(seed))
    if resume_from is None and tc.imitation.epochs > 0:
        if workers.main:
            warm = imitate(policy, adapter, draw_scenarios, world_cfg, sensing, tc, seed)
        warm = workers.from_main(policy, warm)
        if validation:  # the warm-started network is a candidate too (iteration 0): PPO may not improve on it
            judged = validate(policy, adapter, validation, world_cfg, sensing, tc, tolerance, workers)
            warm.update({f"imitation/{k.replace('/', '_')}": v for k, v in judged.items()})
            best = {"iteration": 0, "policy": copy.deepcopy(policy.state_dict())}
        _save(out_dir, config_hash, 0, policy, opt, gen, [], warm, best, workers)  # a kill after it: not redone
    if resume_from is not None:
        state = torch.load(resume_from, map_location="cpu", weights_only=True)
        policy.load_state_dict(state["policy"])
        opt.load_state_dict(state["optimizer"])
        rngs = state.get("worker_rngs", [(state["torch_rng"], state["minibatch_rng"])])
        if len(rngs) != workers.size:
            raise StafpipeError(
                f"train_ppo.resume: {resume_from} was saved by {len(rngs)} workers, this run has {workers.size}"
            )
        torch.set_rng_state(rngs[workers.rank][0])
        gen.set_state(rngs[workers.rank][1])
        history, start = state["history"], int(state["iteration"])
        warm = state.get("warm", {})
        best = state.get("best", {})
        log.info("resumed from iteration %d of %s", start, resume_from)
    bar = progress(range(start, tc.iterations), desc="train-ppo", unit="iteration", initial=start, total=tc.iterations)
    for it in bar:
        began = time.perf_counter()
        rng = np.random.default_rng([seed, it])
        mine = workers.share(tc.worlds)  # every worker draws every world and keeps its own share
        everyone = draw_scenarios(rng, tc.worlds)  # (scenario, its team-centre shortest path, eta) per world
        drawn = [everyone[w] for w in mine]
        worlds = Worlds([d[0] for d in drawn], sensing, world_cfg)
        reset_seeds = [int(x) for x in rng.integers(0, 2**31, tc.worlds)]
        obs = worlds.reset([reset_seeds[w] for w in mine])
        adapter.begin(teams_of(drawn, worlds))
        ro, stats = collect(policy, adapter, worlds, obs, tc, tolerance)
        collected = time.perf_counter()
        adv, ret = gae(ro.rewards, ro.values, ro.last_value, tc.gamma, tc.gae_lambda)
        losses = update(policy, opt, ro, adv, ret, tc, gen, device, workers)
        done = time.perf_counter()
        samples = ro.rewards.numel() * workers.size
        rollout_s, update_s, total_s = workers.total([collected - began, done - collected, done - began], "max")
        done_before = history[-1]["robot_steps"] if history else 0.0  # team sizes differ between iterations
        row = {
            "iteration": it + 1,
            "robot_steps": float(done_before + samples),
            **{f"charts/{k}": v for k, v in workers.mean(stats).items()},
            **losses,
            "charts/fps": samples / total_s,
            "charts/rollout_fps": samples / rollout_s,
            "charts/update_seconds": update_s,
            "charts/log_std": float(policy.log_std.detach().mean()),
        }
        if tc.eval_every and ((it + 1) % tc.eval_every == 0 or it + 1 == tc.iterations):
            worlds = Worlds([d[0] for d in drawn], sensing, world_cfg)  # same scenarios, fixed evaluation seeds
            obs = worlds.reset([EVAL_SEED + w for w in mine])
            adapter.begin(teams_of(drawn, worlds))
            _, ev = collect(policy, adapter, worlds, obs, tc, tolerance, deterministic=True)
            row.update({f"eval/{k}": v for k, v in workers.mean(ev).items()})
            if validation:
                row.update(validate(policy, adapter, validation, world_cfg, sensing, tc, tolerance, workers))
        if it == 0:
            row.update(warm)
        history.append(row)
        if validation and best_iteration(history) == it + 1:
            best = {"iteration": it + 1, "policy": copy.deepcopy(policy.state_dict())}
        bar.set_postfix(sr=f"{stats['success_rate']:.2f}", ret=f"{stats['episode_return']:.1f}")
        if (it + 1) % tc.checkpoint_every == 0 or it + 1 == tc.iterations:
            _save(out_dir, config_hash, it + 1, policy, opt, gen, history, warm, best, workers)
        if workers.main:
            on_iteration(history)
    workers.check_in_step(policy)
    if best:
        policy.load_state_dict(best["policy"])
        log.info("the shipped weights are iteration %d's (best on the validation maps)", best["iteration"])
    return policy, history


def validate(
    policy: PolicyNet,
    adapter: Adapter,
    batches: list[list[Drawn]],
    world_cfg: WorldConfig,
    sensing: SensingConfig,
    tc: TrainPPOConfig,
    tolerance: float,
    workers: Workers = ALONE,
) -> dict[str, float]:
    """The mean action on the held-out worlds (the same seeds every time): `val/success_rate` and
    `val/collisions_per_episode`, averaged over every episode; with `workers`, the batches dealt out among them
    (a batch's result does not depend on who runs it)."""
    episodes, sr, hits = 0, 0.0, 0.0
    for batch in batches[workers.rank :: workers.size]:
        worlds = Worlds([d[0] for d in batch], sensing, world_cfg)
        obs = worlds.reset([VALIDATION_SEED + w for w in range(len(batch))])
        adapter.begin(teams_of(batch, worlds))
        _, ev = collect(policy, adapter, worlds, obs, tc, tolerance, deterministic=True)
        episodes += len(batch)
        sr += ev["success_rate"] * len(batch)
        hits += ev["collisions_per_episode"] * len(batch)
    seen, sr, hits = workers.total([float(episodes), sr, hits])
    return {"val/success_rate": sr / seen, "val/collisions_per_episode": hits / seen}


def best_iteration(history: list[dict[str, float]]) -> int | None:
    """The iteration whose weights are shipped: the highest validation success rate, then the fewest collisions,
    then the earliest; 0 is the warm-started network (judged before the first iteration, its numbers in the first
    row as `imitation/val_*`); None without validation rows."""
    top = best_validation(history)
    return None if top is None else int(top["iteration"])


def best_validation(history: list[dict[str, float]]) -> dict[str, float] | None:
    """The validation row of `best_iteration` (iteration, val/success_rate, val/collisions_per_episode); None without
    validation rows."""
    rows = [r for r in history if "val/success_rate" in r]
    if history and "imitation/val_success_rate" in history[0]:
        first = history[0]
        sr, hits = first["imitation/val_success_rate"], first["imitation/val_collisions_per_episode"]
        rows.insert(0, {"iteration": 0, "val/success_rate": sr, "val/collisions_per_episode": hits})
    if not rows:
        return None
    return max(rows, key=lambda r: (r["val/success_rate"], -r["val/collisions_per_episode"], -r["iteration"]))


def initial_weights(tc: TrainPPOConfig) -> PolicyNet:
    """The network of `train_ppo.init_from`, refused where its method or policy settings differ from this run's."""
    from stafpipe.learning.checkpoint import load_policy

    loaded, _ = load_policy(tc.init_from, tc.method)  # names the file where it is missing or of another method
    ours, theirs = dataclasses.asdict(tc.policy), dataclasses.asdict(loaded.cfg)
    differ = {k: (theirs[k], ours[k]) for k in ours if k != "init_log_std" and ours[k] != theirs.get(k)}
    if differ:
        raise StafpipeError(
            f"train_ppo.init_from: {tc.init_from} was trained with other train_ppo.policy settings "
            f"(checkpoint, this run): {differ}"
        )
    return loaded


def _save(
    out_dir: Path,
    config_hash: str,
    iteration: int,
    policy: PolicyNet,
    opt: torch.optim.Optimizer,
    gen: torch.Generator,
    history: list[dict[str, float]],
    warm: dict[str, float],
    best: dict[str, Any] | None = None,
    workers: Workers = ALONE,
) -> None:
    """The whole training state after `iteration` iterations (0: after the warm start), an exact resume point;
    with several workers, every worker's random states too (`worker_rngs`), written by the main one."""
    rngs = workers.gather((torch.get_rng_state(), gen.get_state()))
    if not workers.main:
        return
    save_payload(
        out_dir / STATE_FILE,
        {
            **({"worker_rngs": rngs} if workers.size > 1 else {}),
            "config_hash": config_hash,
            "iteration": iteration,
            "policy": policy.state_dict(),
            "optimizer": opt.state_dict(),
            "torch_rng": torch.get_rng_state(),
            "minibatch_rng": gen.get_state(),
            "history": history,
            "warm": warm,
            "best": best or {},
        },
    )
