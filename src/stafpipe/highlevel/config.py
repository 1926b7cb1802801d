"""Config dataclasses of STAF's high level (sections `high` and `train_high`); torch-free, so composing configs stays
cheap for stages that never touch a network."""

from __future__ import annotations

from dataclasses import dataclass, field

from stafpipe.devices import check_device
from stafpipe.errors import require
from stafpipe.formations import FORMATION_TYPES

NODE_FEATURES = ("pos", "goal", "heading", "vel")
"""pos: p_i minus the team centroid; goal: g_i minus the goal centroid; heading: unit vector from the team centroid to
the goal centroid (the same for every robot); vel: q_i. Centring makes the cut independent of where the team stands."""


@dataclass
class HighLevelConfig:
    """STAF's high level: the graph-cut network and how it is used (section `high`)."""

    features: list[str] = field(default_factory=lambda: ["pos", "goal", "heading"])
    """Node features (stafpipe.highlevel.graphs.NODE_FEATURES). The paper projects p_i only (W^v 2 x 32); see
    method.md."""
    hidden: int = 32
    """Width of W^v, W^a, W^h (Appendix C: 32)."""
    layers: int = 3
    """Attention layers (Appendix C: three)."""
    heads: int = 4
    """Attention heads per layer, averaged (Section 3 names multi-head attention [54] without a count)."""
    attention: str = "relu"
    """Score nonlinearity: `relu` as printed (Section 3), or `leaky_relu` as in GAT [54]."""
    m_max: int = 4
    """Largest number of subteams the classifier can output."""
    radius: float = 2.0
    """Edge radius of the team graph, metres (Appendix C: 2 m)."""
    m: str = "auto"
    """Subteams at inference: `auto` (smallest m whose subteams fit the narrowest passage, docs/method.md) or a
    number."""
    safe_gap: float = 0.3
    """For m=auto: the free gap (m) kept between neighbouring robots of a subteam at its tightest (docs/method.md)."""
    checkpoint: str = ""
    """A trained checkpoint (`.pt`); empty: the one shipped with the package."""

    def check(self, key: str = "high") -> None:
        for f in self.features:
            require(f in NODE_FEATURES, f"{key}.features", f"entries must be in {list(NODE_FEATURES)}", f)
        require(len(self.features) > 0, f"{key}.features", "must not be empty", self.features)
        require(
            self.hidden > 0 and self.layers > 0 and self.heads > 0,
            f"{key}.hidden/layers/heads",
            "must be > 0",
            (self.hidden, self.layers, self.heads),
        )
        require(
            self.attention in ("relu", "leaky_relu"), f"{key}.attention", "must be relu or leaky_relu", self.attention
        )
        require(self.m_max >= 2, f"{key}.m_max", "must be >= 2", self.m_max)
        require(self.radius > 0, f"{key}.radius", "must be > 0", self.radius)
        require(
            self.m == "auto" or (self.m.isdigit() and int(self.m) >= 1),
            f"{key}.m",
            "must be `auto` or an integer >= 1",
            self.m,
        )
        if self.m != "auto":
            require(int(self.m) <= self.m_max, f"{key}.m", f"must be <= high.m_max ({self.m_max})", self.m)
        require(self.safe_gap >= 0, f"{key}.safe_gap", "must be >= 0", self.safe_gap)


@dataclass
class LossWeights:
    """Weights of the three terms of Eq. (1); 0 switches a term off (the ablation of STAF Fig. 7)."""

    adjacency: float = 1.0
    balance: float = 1.0
    goal: float = 1.0

    def check(self, key: str) -> None:
        values = [self.adjacency, self.balance, self.goal]
        require(all(v >= 0 for v in values), key, "weights must be >= 0", values)
        require(any(v > 0 for v in values), key, "at least one weight must be > 0", values)


@dataclass
class TrainHighConfig:
    """Training of the high level (section `train_high`)."""

    data: str = ""
    """A `formations.parquet` of `stafpipe generate` (or its run directory); empty: generate from `data` in memory."""
    epochs: int = 100
    """Training epochs (STAF Appendix C: 100)."""
    batch_size: int = 128
    """Teams per gradient step."""
    lr: float = 1e-3
    """Adam learning rate."""
    val_fraction: float = 0.1
    """Share of the teams held out to report validation losses."""
    m_choices: list[int] = field(default_factory=lambda: [2, 3, 4])
    """Each team, each epoch, is cut into m subteams drawn from this list (capped at n - 1)."""
    loss: LossWeights = field(default_factory=LossWeights)
    threads: int = 1
    """torch threads. 1: the same weights for a seed on every run (measured: two runs of the loss-term
    ablation with 2 threads gave weights up to 0.24 apart, with 1 thread bit-identical) and no slower on 2 cores
    (10 epochs: 32 s against 34 s with 2; two 2-thread runs side by side took 7x as long, docs/method.md)."""
    device: str = "cpu"
    """Where the network and its training run: `cpu`, or `cuda` / `cuda:N` where the machine has one (a clear error
    where it has not). The data are built on the CPU; the checkpoint is saved for the CPU either way."""

    def check(self, key: str = "train_high") -> None:
        require(self.epochs >= 1, f"{key}.epochs", "must be >= 1", self.epochs)
        require(self.batch_size >= 1, f"{key}.batch_size", "must be >= 1", self.batch_size)
        require(self.lr > 0, f"{key}.lr", "must be > 0", self.lr)
        require(0 <= self.val_fraction < 1, f"{key}.val_fraction", "must be in [0, 1)", self.val_fraction)
        require(
            len(self.m_choices) > 0 and all(m >= 2 for m in self.m_choices),
            f"{key}.m_choices",
            "must be a non-empty list of integers >= 2",
            list(self.m_choices),
        )
        require(self.threads >= 1, f"{key}.threads", "must be >= 1", self.threads)
        check_device(self.device, f"{key}.device")
        self.loss.check(f"{key}.loss")


STUDIES = ("loss_terms", "subteam_count", "noise", "classical")
LOSS_VARIANTS: dict[str, tuple[float, float, float] | None] = {
    # STAF Fig. 7 (Section 5): (adjacency, balance, goal) weights; None = `train_high.loss` (the full loss)
    "a_balance_only": (0.0, 1.0, 0.0),
    "b_adjacency_only": (1.0, 0.0, 0.0),
    "c_goal_only": (0.0, 0.0, 1.0),
    "d_without_balance": (1.0, 0.0, 1.0),
    "e_without_adjacency": (0.0, 1.0, 1.0),
    "f_without_goal": (1.0, 1.0, 0.0),
    "full": None,
}


@dataclass
class AblateConfig:
    """The graph-cut studies of `stafpipe ablate` (section `ablate`)."""

    study: str = "loss_terms"
    """loss_terms (STAF Fig. 7), subteam_count (Fig. 9), noise (Fig. 14), classical (learned vs spectral vs k-means)."""
    teams: int = 200
    """Test teams per setting (drawn with `seed`, disjoint from training draws)."""
    n: int = 12
    """Team size of the loss_terms and noise studies (Fig. 7: 12 robots)."""
    m: int = 3
    """Subteams of the loss_terms study (Fig. 7: 3) and the noise study uses 2 (Fig. 14)."""
    formation: str = "circle"
    """Formation of the loss_terms and noise studies."""
    variants: list[str] = field(default_factory=lambda: list(LOSS_VARIANTS))
    """loss_terms: which loss variants to train (each its own network); `full` uses `train_high.loss`."""
    train_instances: int = 2000
    """loss_terms: training teams per variant."""
    epochs: int = 40
    """loss_terms: training epochs per variant."""
    formations: list[str] = field(default_factory=lambda: ["circle", "wedge", "line"])
    """subteam_count and classical: formations to test (Fig. 9: circle, wedge, line)."""
    m_values: list[int] = field(default_factory=lambda: [2, 3, 4])
    """subteam_count and classical: numbers of subteams (Fig. 9: 2, 3, 4)."""
    team_size: int = 10
    """subteam_count and classical: team size."""
    noise_sigmas: list[float] = field(default_factory=lambda: [0.0, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0])
    """noise: standard deviations (m) of the Gaussian noise added to positions (Appendix F, Fig. 14)."""
    noise_m: int = 2
    """noise: subteams (Fig. 14 divides the team in two)."""

    def check(self, key: str = "ablate") -> None:
        require(self.study in STUDIES, f"{key}.study", f"must be one of {list(STUDIES)}", self.study)
        require(self.teams >= 1, f"{key}.teams", "must be >= 1", self.teams)
        require(self.n >= 3 and 2 <= self.m < self.n, f"{key}.n/m", "need n >= 3 and 2 <= m < n", (self.n, self.m))
        for v in self.variants:
            require(v in LOSS_VARIANTS, f"{key}.variants", f"entries must be in {list(LOSS_VARIANTS)}", v)
        require(
            self.train_instances >= 1 and self.epochs >= 1,
            f"{key}.train_instances/epochs",
            "must be >= 1",
            (self.train_instances, self.epochs),
        )
        require(all(m >= 2 for m in self.m_values), f"{key}.m_values", "must be >= 2", list(self.m_values))
        require(
            self.team_size > max(self.m_values, default=2), f"{key}.team_size", "must exceed every m", self.team_size
        )
        require(all(s >= 0 for s in self.noise_sigmas), f"{key}.noise_sigmas", "must be >= 0", list(self.noise_sigmas))
        require(2 <= self.noise_m < self.n, f"{key}.noise_m", f"must be in [2, ablate.n = {self.n})", self.noise_m)
        for kind in [self.formation, *self.formations]:
            require(kind in FORMATION_TYPES, f"{key}.formation(s)", f"must be in {list(FORMATION_TYPES)}", kind)
