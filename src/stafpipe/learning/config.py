"""Config dataclasses of `stafpipe train-ppo` (section `train_ppo`); torch-free."""

from __future__ import annotations

from dataclasses import dataclass, field

from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.errors import require
from stafpipe.formations import FORMATION_TYPES
from stafpipe.methods.staf.subteaming import SubteamingConfig
from stafpipe.registry import learned_methods


@dataclass
class RewardConfig:
    """Per-robot reward of one control step. Defaults: DGNN's public training code (Blumenkamp et al., ICRA 2022), as
    the papers README records it: -1.5 per robot-robot collision, -0.25 per wall contact, a dense progress term, +10 at
    the goal."""

    progress: float = 1.0
    """Per metre the robot got closer to its goal this step."""
    goal: float = 10.0
    """Once, when the robot first comes within `eval.goal_tolerance` of its goal."""
    robot_collision: float = -1.5
    """Each step the robot touches another robot."""
    wall_contact: float = -0.25
    """Each step the robot touches an obstacle."""
    contact_tolerance: float = 0.02
    """Surfaces closer than this (m) count as touching."""
    formation: float = 0.1
    """method=staf_planned: weight of STAF's spring-damper term R^adp (Sec. 3) in the per-robot reward (0 for dgnn: DGNN
    has no formation term)."""
    adp_lambda: float = 0.6
    """lambda of R^adp = sum -lambda |d_ij - p_ij| - (1 - lambda) q_ij (STAF Sec. 3; 0.6 in App. C)."""
    proximity: float = 0.1
    """method=staf_planned: penalty per neighbour or obstacle closer than `safe_distance`, growing linearly to this at
    contact (STAF Sec. 3: "a penalty when a robot comes too close to nearby obstacles or other robots")."""
    safe_distance: float = 0.15
    """Surface gap (m) below which the proximity penalty starts."""


@dataclass
class PolicyConfig:
    """The DGNN policy (Blumenkamp et al. 2022): per-robot encoder, message passing over neighbours within the
    communication radius, MLP actor; a critic head on the same features plus the team mean (a centralized critic)."""

    hidden: int = 64
    message_layers: int = 1
    """Rounds of message passing (neighbours' neighbours are reached with 2)."""
    goal_clip: float = 5.0
    """The target vector is clipped to this length (m) before it enters the network."""
    guide: str = "path"
    """Target: `goal` (straight to the robot's own goal) or `path` (ahead on the path through the middle of the
    passages, episode.centred_path, not the team's shortest path, which hugs walls; features.py)."""
    lookahead: float = 2.0
    """guide=path: how far ahead on the path the target lies (m)."""
    release: float = 4.0
    """guide=path: within this distance of the path's end the target becomes the robot's own goal (m)."""
    init_log_std: float = -0.5
    prior_gain: float = 0.0
    """method=staf_planned: 0 = a_i = psi(f_i) as printed; > 0 adds a proportional step towards the target (gain x
    target vector, at most unit length) to psi's output, which then learns a residual (docs/staf_planned.md)."""
    message: str = "relu"
    """method=staf_planned: the intermediate GNN's neighbour message, `linear` (as printed, Sec. 3) or `relu`
    (learning/staf_net.py)."""
    drive_input: bool = False
    """method=staf_planned: true appends to each robot's own state a flag of its drive (1 a differential drive, 0
    holonomic; a robot knows its own drive), so that one network can act differently on each where their states look
    the same (the `sliding` teacher's differential-drive cap, docs/staf_planned.md); false: the state as printed (Sec.
    3)."""


@dataclass
class ImitationConfig:
    """Warm start before PPO (`learning/ppo.py:imitate`): the network imitates a hand-made low level (`teacher`,
    learning/teachers.py), then PPO trains it alone. A teacher for the first minutes only, never part of the trained
    policy's action."""

    epochs: int = 0
    """Passes of supervised regression over the teacher's samples; 0: no warm start."""
    rollouts: int = 1
    """Batches of `worlds` episodes of `episode_steps` steps driven by the teacher (with `noise`) to collect states;
    as many again in each DAgger round."""
    dagger: int = 0
    """DAgger rounds after the first fit: the network drives (its mean action + `noise`), the teacher labels, all
    samples are kept and the fit continues (Ross, Gordon and Bagnell, AISTATS 2011)."""
    teacher: str = "proportional"
    """`proportional` (a step to the target), `avoiding` (the same, with the classical methods' approach cap near
    robots and obstacles), `sliding` (`avoiding` aiming no closer to the closest obstacle than a margin, and on a
    differential drive capping the motion the drive makes as well), `capped` (`avoiding` with that second cap only) or
    `orca`, learning/teachers.py."""
    gain: float = 2.0
    """The teacher's gain: a step of min(1, gain x distance) of top speed towards the target."""
    stop_gap: float = 0.02
    """m: the gap to robots and obstacles the teacher's approach cap brakes to (`avoiding`, `sliding`, `capped`);
    0.02: the classical methods' (controllers/base.py STOP_GAP), as earlier recipes used."""
    noise: float = 0.3
    """Standard deviation of the noise added to the teacher's actions while collecting (states off its own way)."""
    near_weight: float = 1.0
    """Weight of the samples where the teacher brakes for a neighbour or an obstacle (its action differs from the
    free proportional step) against 1 for the rest; 1: plain regression."""
    direction_weight: float = 0.0
    """Weight of a direction term, 1 - cos(network action, teacher action), added to each sample's squared error
    (`ppo.imitation_loss`): a scaled-down command (the `sliding` teacher's near a robot or an obstacle) is a short
    target whose direction the squared error weighs little, while a differential drive turns towards that direction
    at its full turn rate whatever the command's length (drives.diff_drive); 0: none."""
    wall_copies: float = 0.0
    """Fraction of the collected steps to which a relabelled copy is added: every robot's closest obstacle replaced
    by a wall point at a random bearing 0-0.4 m from its surface (`teachers.near_wall_copy`), the teacher's action on
    it the label; 0: none."""
    neighbour_copies: float = 0.0
    """The same with each robot's nearest sensed neighbour moved, in that robot's view, to a random bearing 0-0.4 m
    from its surface (`teachers.near_neighbour_copy`); 0: none."""
    privileged: bool = False
    """method=staf_planned with `plan.adapt=nominal`: true, the teacher drives to the targets of a shadow plan with the
    geometric adaptation, which the network never sees (it must infer the shrink from what it senses; measured
    worse, the STAF-planned journal (docs/staf_planned.md) "Learned adaptation"); false, the teacher drives to the
    plan's own nominal targets, as the
    network sees them, and deforms the formation only by braking for walls and robots."""
    lr: float = 1e-3
    batch: int = 256
    """World-steps per minibatch."""


@dataclass
class TrainPPOConfig:
    """PPO on batched worlds (section `train_ppo`). Each iteration resets its worlds and runs one episode of
    `episode_steps` steps in each, so an iteration boundary is an exact resume point."""

    method: str = "dgnn"
    """The learned method to train (its adapter, learning/adapters.py): `dgnn` (the baseline) or `staf_planned`
    (STAF-planned, ours: STAF's intermediate + low level, on the targets of our plan with the high level fixed: one
    round of App. B.1)."""
    iterations: int = 100
    """Training iterations (about 10 min on 2 cores with the defaults; DGNN solves the corridor in about 60)."""
    worlds: int = 16
    """B: worlds stepped together per rollout."""
    episode_steps: int = 400
    """Control steps per episode (x world.control_dt s); a truncation, bootstrapped from the value."""
    scenarios: list[str] = field(default_factory=lambda: ["corridor"])
    """Curriculum: each world of each iteration draws one of these: built-in scenario names, scenario files, or
    directories of scenario files (every `*.yaml` in them, e.g. the `maps/` of `stafpipe generate-maps`)."""
    formations: list[str] = field(default_factory=lambda: ["circle", "wedge", "line"])
    """Curriculum: ... and one of these team formations (STAF Table 1's three); empty: the scenario's own (or the
    `formation` group's)."""
    team_sizes: list[int] = field(default_factory=list)
    """Curriculum: ... and each of these team sizes (one size per iteration: a batch shares n); empty: the
    scenario's."""
    validation: list[str] = field(default_factory=list)
    """Held-out scenarios (names, files or directories, never trained on) for choosing the shipped weights: at each
    `eval_every` iteration the mean action runs `validation_episodes` seeded episodes on them, and `policy.pt` holds
    the weights of the iteration with the highest validation success rate (ties: fewer collisions, then the earlier).
    Empty: `policy.pt` holds the last iteration's weights."""
    validation_episodes: int = 16
    """Episodes per validation point (spread over the validation scenarios, the same seeds every time)."""
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.2
    """PPO's clip delta (STAF Eq. (2) writes clip(., 1 - lambda, 1 + lambda) without a value; 0.2 as in PPO [67])."""
    epochs: int = 4
    minibatches: int = 4
    lr: float = 3e-4
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    eval_every: int = 5
    """Every this many iterations, one more batch of episodes with the policy's mean action (no update): the
    `eval/success_rate` curve, comparable with `stafpipe eval method=dgnn`. 0 switches it off."""
    checkpoint_every: int = 10
    """Iterations between checkpoints of the full training state."""
    init_from: str = ""
    """A policy checkpoint (`policy.pt` of an earlier run, or a shipped one) whose weights, action std included,
    start this run instead of fresh ones: fine-tuning. Its method and `policy` settings must equal this run's. With
    `imitation.epochs` > 0 every imitation round is then a DAgger round (the loaded network drives)."""
    resume: bool = False
    """Continue from the newest state of the same config (this run directory first, then outputs/train-ppo/)."""
    threads: int = 2
    """Torch threads of each training process."""
    workers: int = 1
    """Training processes (DD-PPO, learning/distributed.py): each steps `worlds / workers` of the worlds and
    computes the update's gradients on its own samples, averaged over the workers at every minibatch; started on this
    machine by torch.distributed's elastic launcher (torchrun's). A seed and the number of workers fix the result;
    1 runs in this process with no torch.distributed at all. The warm start runs on one worker."""
    device: str = "cpu"
    """Where the PPO update runs: `cpu`, or `cuda` / `cuda:N` where the machine has one (a clear error where it has
    not). The rollouts (simulator, features, the policy's forward pass) stay on the CPU; the checkpoint is for the
    CPU either way."""
    reward: RewardConfig = field(default_factory=RewardConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    imitation: ImitationConfig = field(default_factory=ImitationConfig)
    plan: PlanConfig = field(default_factory=PlanConfig)
    """method=staf_planned: the execution plan (subteams, sequencing, regroup) the policy is trained on; an eval of
    `method=staf_planned` must use the same settings."""
    subteaming: SubteamingConfig = field(default_factory=SubteamingConfig)
    """method=staf: the paper's rules (m, subteam goals, turns, regroup; methods/staf/subteaming.py) the policy is
    trained under; an eval of `method=staf` must use the same settings."""

    def check(self, key: str = "train_ppo") -> None:
        learned = learned_methods()
        require(self.method in learned, f"{key}.method", f"must be one of {learned}", self.method)
        im = self.imitation
        require(
            im.epochs >= 0 and im.rollouts >= 1 and im.batch >= 1 and im.dagger >= 0,
            f"{key}.imitation",
            "epochs >= 0, rollouts >= 1, batch >= 1, dagger >= 0",
            (im.epochs, im.rollouts, im.batch, im.dagger),
        )
        from stafpipe.learning.teachers import TEACHERS

        require(im.teacher in TEACHERS, f"{key}.imitation.teacher", f"must be one of {list(TEACHERS)}", im.teacher)
        require(
            im.gain > 0 and im.noise >= 0 and im.lr > 0 and im.near_weight > 0 and im.direction_weight >= 0,
            f"{key}.imitation",
            "gain > 0, noise >= 0, lr > 0, near_weight > 0, direction_weight >= 0",
            (im.gain, im.noise, im.lr, im.near_weight, im.direction_weight),
        )
        from stafpipe.learning.teachers import check_stop_gap

        check_stop_gap(im.stop_gap, f"{key}.imitation.stop_gap")
        for name in ("wall_copies", "neighbour_copies"):
            value = getattr(im, name)
            require(0.0 <= value <= 1.0, f"{key}.imitation.{name}", "must be in [0, 1]", value)
        for name in ("iterations", "worlds", "episode_steps", "epochs", "minibatches", "checkpoint_every", "threads"):
            require(getattr(self, name) >= 1, f"{key}.{name}", "must be >= 1", getattr(self, name))
        require(self.workers >= 1, f"{key}.workers", "must be >= 1", self.workers)
        require(
            self.worlds % self.workers == 0,
            f"{key}.worlds",
            f"must be a multiple of train_ppo.workers ({self.workers}): each worker steps an equal share",
            self.worlds,
        )
        require(self.eval_every >= 0, f"{key}.eval_every", "must be >= 0", self.eval_every)
        if self.policy.drive_input:
            from stafpipe.registry import adapter_class

            require(
                adapter_class(self.method).network.reads_drive_flag,
                f"{key}.policy.drive_input",
                "is read by the STAF network only (method=staf, method=staf_planned)",
                self.method,
            )
        from stafpipe.devices import check_device

        check_device(self.device, f"{key}.device")
        require(self.validation_episodes >= 1, f"{key}.validation_episodes", "must be >= 1", self.validation_episodes)
        require(
            not self.validation or self.eval_every >= 1,
            f"{key}.eval_every",
            "must be >= 1 with validation",
            self.eval_every,
        )
        for kind in self.formations:
            require(kind in FORMATION_TYPES, f"{key}.formations", f"entries must be in {list(FORMATION_TYPES)}", kind)
        for n in self.team_sizes:
            require(n >= 2, f"{key}.team_sizes", "entries must be >= 2", n)
        require(len(self.scenarios) > 0, f"{key}.scenarios", "must name at least one scenario", self.scenarios)
        require(
            0 < self.gamma <= 1 and 0 <= self.gae_lambda <= 1,
            f"{key}.gamma/gae_lambda",
            "must be in (0, 1]",
            (self.gamma, self.gae_lambda),
        )
        require(0 < self.clip < 1, f"{key}.clip", "must be in (0, 1)", self.clip)
        require(self.lr > 0, f"{key}.lr", "must be > 0", self.lr)
        require(
            self.worlds // max(1, self.workers) * self.episode_steps >= self.minibatches,
            f"{key}.minibatches",
            "must not exceed worlds / workers x episode_steps (a worker's samples)",
            self.minibatches,
        )
        require(self.policy.guide in ("goal", "path"), f"{key}.policy.guide", "must be goal or path", self.policy.guide)
        require(
            self.policy.message in ("linear", "relu"),
            f"{key}.policy.message",
            "must be linear or relu",
            self.policy.message,
        )
        require(
            0 <= self.reward.adp_lambda <= 1, f"{key}.reward.adp_lambda", "must be in [0, 1]", self.reward.adp_lambda
        )
        self.plan.check(f"{key}.plan")
        self.subteaming.check(f"{key}.subteaming")
        require(
            self.policy.hidden >= 1 and self.policy.message_layers >= 0,
            f"{key}.policy",
            "hidden >= 1, message_layers >= 0",
            (self.policy.hidden, self.policy.message_layers),
        )
