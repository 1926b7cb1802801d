"""The evaluation controller of every learned method: its policy checkpoint driven through the method's adapter
(learning/adapters.py), exactly as the PPO rollout drives it, on a batch of worlds: the adapter's features and plans
for every world of the batch in one pass, then one network call per world (`_world_mean`)."""

from __future__ import annotations

import dataclasses
import logging
import math
import zlib
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from stafpipe.controllers.base import STOP_GAP, Controller, Event, TeamInfo, forward_capped, limit_approach
from stafpipe.controllers.orca import avoid_movers
from stafpipe.errors import StafpipeError
from stafpipe.learning.checkpoint import ensemble_paths, load_members, load_policy
from stafpipe.learning.config import RewardConfig
from stafpipe.learning.rollout import commands
from stafpipe.learning.teachers import AVOID_DISTANCE, AVOID_GAIN, teacher_actions
from stafpipe.registry import adapter_class
from stafpipe.sensing import Observation

if TYPE_CHECKING:
    from stafpipe.learning.adapters import Adapter

log = logging.getLogger(__name__)


PLAN_SAFEGUARDS = (
    "home",
    "target_gap",
    "home_approach",
    "unblock",
    "extend_path",
    "end_home",
    "end_wait",
    "in_sight",
    "sight_wait",
    "reorder",
    "reorder_lateral",
    "in_world",
    "separate_in_world",
    "lead_past_end",
    "cut_frame",
    "start_slots",
    "hold_short",
    "sight_clear",
    "track_progress",
)
"""Plan settings that only keep targets from crossing, crowding, running into robots already home or leaving the world
(docs/staf_planned.md): a policy trained without them runs with them, so they are not compared with its training
record."""


def checkpoint_mismatch(cfg: Any, made_by: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    """Settings of this run that differ from those the checkpoint recorded at training (`made_by`): the method's plan
    settings (`method.<plan_key>.*` against `train_ppo.<plan_key>.*`, the adapter's `plan_key`: `plan` for
    staf_planned, `subteaming` for staf) and the sensing radius (against `sensing.radius`), as far as the checkpoint
    recorded them (a setting it did not record was added later, with a default that keeps the old behaviour). Key ->
    (this run's value, the training value)."""
    trained = made_by.get("train_ppo", {})
    differ: dict[str, tuple[Any, Any]] = {}
    field = adapter_class(cfg.name).plan_key
    plan, recorded = getattr(cfg, field, None), trained.get(field)
    skip = PLAN_SAFEGUARDS if field == "plan" else ()
    if plan is not None and isinstance(recorded, dict):
        for key, value in dataclasses.asdict(plan).items():
            if key in recorded and recorded[key] != value and key not in skip:
                differ[f"method.{field}.{key}"] = (value, recorded[key])
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
        self._check_made_by(cfg.checkpoint or f"the shipped {cfg.name} policy", self.made_by)
        # frozen actions (the weights never change here): the checkpoint's, then those of `method.ensemble`, more
        # training runs of the same network whose action means are averaged
        # (the STAF-planned journal (docs/staf_planned.md), "Several training runs
        # averaged")
        paths = ensemble_paths(cfg.checkpoint, getattr(cfg, "ensemble", []), cfg.name)
        self._acts = [self.policy.frozen_act()]
        speeds = [self.made_by.get("max_speed")]
        for k, (path, member, made_by) in enumerate(load_members(paths, self.policy, cfg.name, "method.ensemble")):
            self._check_made_by(f"method.ensemble[{k}] ({path})", made_by)
            self._acts.append(member.frozen_act())
            speeds.append(made_by.get("max_speed"))
        # A network's action is a fraction of the top speed of the robots it was trained with (`made_by.max_speed`):
        # robots faster than those are driven no faster, since the network's braking was learned at that speed
        # (docs/decisions.md, "Robots faster than the training's"); a record without it: the robot's own top speed
        known = [float(v) for v in speeds if v is not None]
        self.trained_speed = min(known) if known else math.inf
        if paths:  # the run's config may leave `method.ensemble` unset: its log says what acted
            runs = [cfg.checkpoint or f"shipped:{cfg.name}", *paths]
            log.info("%s acts with the mean action of %d runs: %s", cfg.name, len(runs), ", ".join(runs))
        kind = adapter_class(cfg.name)
        self._set_up(kind(self.policy.cfg, RewardConfig(), getattr(cfg, kind.plan_key, None), cfg.sensing_radius))

    def _set_up(self, adapter: Adapter) -> None:
        """What acting needs besides the network: the method's adapter (features, targets, subteams), one thread
        and the speed state; every learned controller's constructor ends here."""
        self.adapter = adapter
        # One thread: a parallel matrix product sums in another order, and a closed loop grows the last bit into
        # another trajectory (measured: DGNN's corridor wedge, 1 vs 2 threads, other TT in 4 of 5 episodes). With
        # one thread the seed fixes the episode on any number of cores; these networks are no slower with it.
        torch.set_num_threads(1)
        self.max_speed = self.command_speed = 1.0
        self._capped_at = math.inf  # the cap last logged (once per eval, not per episode)
        self.last_time = 0.0

    def _check_made_by(self, where: str, made_by: dict[str, Any]) -> None:
        """Refuse (or, with method.allow_mismatch, warn about) a checkpoint trained with other settings."""
        differ = checkpoint_mismatch(self.cfg, made_by) if self.teacher == "learned" else {}
        if differ:
            text = "; ".join(f"{k}: this run {a!r}, trained with {b!r}" for k, (a, b) in differ.items())
            if not getattr(self.cfg, "allow_mismatch", False):
                raise StafpipeError(
                    f"{where} was trained with other settings than this run ({text}); retrain it, "
                    "or set method.allow_mismatch=true to run it anyway"
                )
            log.warning("%s was trained with other settings than this run: %s", where, text)

    def reset(self, team: TeamInfo) -> None:
        self.reset_worlds([team])

    def act(self, obs: Observation) -> np.ndarray:
        batch = Observation(*(np.asarray(x)[None] for x in obs))  # a batch of one world
        return self.act_worlds(batch, np.ones(1, dtype=bool))[0]

    @property
    def subteams(self) -> np.ndarray:
        return self._worlds[0].subteams

    @property
    def targets(self) -> np.ndarray:
        return self._worlds[0].targets

    def drain_events(self) -> list[Event]:
        return self._worlds[0].drain_events()

    def reset_worlds(self, teams: list[TeamInfo]) -> None:
        """Every world's episode in the one adapter, so that each step computes the batch's features in one pass."""
        self.n = len(teams[0].start)
        self.max_speed = teams[0].scenario.spec.robot.max_speed
        self.command_speed = min(self.max_speed, self.trained_speed) if self.teacher == "learned" else self.max_speed
        if self.command_speed < self.max_speed and self.command_speed != self._capped_at:
            self._capped_at = self.command_speed
            log.info(
                "%s: robots of top speed %g m/s are driven at most %g m/s, the top speed the network was trained with",
                self.cfg.name,
                self.max_speed,
                self.command_speed,
            )
        self.adapter.begin(teams)
        self.last_time = 0.0
        self._worlds = [Controller() for _ in teams]  # each world's subteams, targets and events
        for view, team in zip(self._worlds, teams, strict=True):
            Controller.reset(view, team)
        # Sampled actions (deterministic=false): one noise stream per world, seeded by its start, so that a world's
        # episode does not depend on the batch it ran in nor on the episodes before it.
        self.generators = [torch.Generator().manual_seed(zlib.crc32(t.start.tobytes())) for t in teams]

    def act_worlds(self, obs: Observation, active: np.ndarray) -> np.ndarray:
        time = float(obs.time[0])  # the worlds of a batch share one clock
        dt, self.last_time = time - self.last_time, time
        f, _, targets = self.adapter.step(obs, dt)
        subteams = self.adapter.subteams()
        for w in np.flatnonzero(active).tolist():
            view = self._worlds[w]
            view._targets, view._subteams = targets[w].copy(), subteams[w].copy()
            for kind, robots, detail in self.adapter.drain_events(w):
                view.emit(kind, robots, detail)
        if self.teacher != "learned":
            robot = self.adapter.teams[0].scenario.spec.robot
            action = teacher_actions(
                self.teacher,
                self.adapter.teacher_aim() - obs.position,  # the imitation teacher's aim (Adapter.teacher_aim)
                obs,
                robot.radius,
                self.max_speed,
                self.cfg.proportional_gain,
                robot.drive,
                getattr(self.cfg, "stop_gap", STOP_GAP),
            )
        else:
            action = np.zeros(obs.position.shape, dtype=np.float32)  # the network's dtype, as `commands` always took it
            with torch.inference_mode():  # execution: no critic, no autograd bookkeeping
                for w in np.flatnonzero(active).tolist():
                    action[w] = self._world_mean(f, w).numpy()
        out = commands(action, obs.heading, self.command_speed)
        if getattr(self.cfg, "approach_cap", False):
            out = self._approach_capped(out, obs)
        out[~active] = 0.0
        if getattr(self.cfg, "avoid_movers", False):
            self._avoid_movers(out, obs, active)
        return out

    def _approach_capped(self, out: np.ndarray, obs: Observation) -> np.ndarray:
        """`method.approach_cap`: the classical methods' approach cap on the commands of every world at once, and on a
        differential drive's motion from them (the STAF-planned journal (docs/staf_planned.md), "A safety layer")."""
        robot = self.adapter.teams[0].scenario.spec.robot  # the worlds of a batch share one robot
        gap = self.cfg.approach_cap_gap
        out = limit_approach(out, obs, robot.radius, AVOID_DISTANCE, AVOID_GAIN, gap)
        if robot.drive == "diff_drive":
            out = forward_capped(out, obs, robot.radius, AVOID_DISTANCE, AVOID_GAIN, gap)
        return out

    def _avoid_movers(self, out: np.ndarray, obs: Observation, active: np.ndarray) -> None:
        """`method.avoid_movers`: in the worlds with moving obstacles, the commands with the movers avoided
        (`orca.avoid_movers`; the STAF-planned journal (docs/staf_planned.md), "Moving obstacles"). Worlds without any
        are left as they are."""
        for w in np.flatnonzero(active).tolist():
            spec = self.adapter.teams[w].scenario.spec
            if spec.moving_obstacles:
                radii = np.array([m.radius for m in spec.moving_obstacles])
                out[w] = avoid_movers(out[w], obs.world(w), spec.robot.radius, self.command_speed, radii)

    def _world_mean(self, f: Any, w: int) -> torch.Tensor:
        """(n, 2) world w's action (its mean, or a sample from its own noise stream). One network call per world, on
        fresh copies of its rows: a matrix product's rounding may depend on how many rows it is given and on their
        place in memory (a CPU's BLAS picks its kernel by shape; CI saw a batch of three DGNN or STAF worlds act
        differently in the last bit from each world alone, which the closed loop grew into other episodes), so a
        world acts exactly as it would alone. It costs about 2.5x the network time of one call for 50 worlds
        (docs/decisions.md)."""
        own, edge, mask = (torch.from_numpy(x[w : w + 1]).clone() for x in (f.own, f.edge, f.mask))
        # with `method.ensemble`, the members' mean action; sampling (deterministic=false) uses the checkpoint's spread
        means = [act(own, edge, mask)[0] for act in self._acts]
        mean = means[0] if len(means) == 1 else torch.stack(means).mean(0)
        if not self.cfg.deterministic:
            mean = mean + self.policy.log_std.exp() * torch.randn(mean.shape, generator=self.generators[w])
        return mean

    def world_view(self, w: int) -> Controller:
        return self._worlds[w]
