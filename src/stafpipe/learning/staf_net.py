"""STAF's intermediate and low levels (STAF, Sec. 3; App. C), one policy shared by all robots.

Intermediate level phi: z_i = W^z s_i, f_i = W^f z_i + sum_{j in N(i)} W^f (z_j - z_i) (Sec. 3), W^z 6 x 64 -> here
9 x 64 on the robot-frame state of features.staf_features (the own state has 6 entries, as App. C's 6 x 64; the
neighbours' difference adds the relative position, the target offset and the subteam flag), W^f 64 x 64 (App. C). Low
level psi: two linear layers with a ReLU, f_i -> a_i = [v_x, v_y] (Sec. 3), the mean of a Gaussian policy for PPO.

`message=linear` is phi as printed: the whole policy is then a one-hidden-layer network of s_i and sum_j (s_j - s_i),
which cannot tell one close neighbour from several far ones. `message=relu` (default) passes each neighbour's
W^f (z_j - z_i) + b through a ReLU before the sum, so a close robot can be told from the rest: docs/staf_planned.md
compares
the two.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from stafpipe.learning.config import PolicyConfig
from stafpipe.learning.features import STAF_EDGE, STAF_OWN
from stafpipe.learning.policy_net import PolicyNet


def proportional_step(own: torch.Tensor, gain: float) -> torch.Tensor:
    """(.., 2) the residual prior (`policy.prior_gain` > 0): a step towards the target at min(1, gain x distance) of top
    speed, `own[..., :2]` being the robot-frame target vector (learning/teachers.py takes the same step in numpy)."""
    step = gain * own[..., :2]
    return step / step.norm(dim=-1, keepdim=True).clamp_min(1.0)


class StafPolicy(PolicyNet):
    """phi (W^z, W^f) + psi, and a critic head (own embedding and the team's mean: a centralized critic)."""

    reads_drive_flag = True
    own_features, edge_features = STAF_OWN, STAF_EDGE

    def __init__(self, cfg: PolicyConfig):
        super().__init__()
        h = cfg.hidden
        self.cfg = cfg
        self.w_z = nn.Linear(STAF_EDGE, h, bias=False)  # z = W^z s; own state's entries are a slice of s (below)
        self.b_z = nn.Parameter(torch.zeros(h))  # the own state's constant part (its origin and same_ii = 1)
        self.w_f = nn.Linear(h, h, bias=False)
        self.b_msg = nn.Parameter(torch.zeros(h))  # threshold of the ReLU message (message=relu only)
        self.psi = nn.Sequential(nn.Linear(h, h), nn.ReLU(), nn.Linear(h, 2))
        self.critic = nn.Sequential(nn.Linear(2 * h, h), nn.ReLU(), nn.Linear(h, 1))
        self.log_std = nn.Parameter(torch.full((2,), cfg.init_log_std))
        if cfg.drive_input:  # z_i gains w_drive where robot i has a differential drive (own's 7th entry)
            self.w_drive = nn.Parameter(torch.zeros(h))
        if cfg.prior_gain > 0:  # a residual starts at zero: the untrained policy is the proportional step itself
            last = self.psi[2]
            assert isinstance(last, nn.Linear)
            nn.init.zeros_(last.weight)
            nn.init.zeros_(last.bias)

    def _own_embedding(self, own: torch.Tensor) -> torch.Tensor:
        """z_i = W^z s_i: s_i in its own frame is [0, 0, own, 1] (p_i - p_i = 0, same_ii = 1), so W^z s_i =
        W^z[:, 2:8] own + W^z[:, 8] + b; with `drive_input`, + w_drive x own's drive flag."""
        z = own[..., :STAF_OWN] @ self.w_z.weight[:, 2 : 2 + STAF_OWN].T + self.w_z.weight[:, 2 + STAF_OWN] + self.b_z
        if self.cfg.drive_input:
            z = z + own[..., STAF_OWN : STAF_OWN + 1] * self.w_drive
        return z

    def _pair_map(self) -> torch.Tensor:
        """(9, hidden) (W^f W^z)^T, the map `_message` applies to each pair."""
        return (self.w_f.weight @ self.w_z.weight).T

    def _message(self, diff: torch.Tensor, pair_map: torch.Tensor | None = None) -> torch.Tensor:
        """W^f (z_j - z_i) for each pair, diff = s_j - s_i (.., 9): z_j - z_i = W^z (s_j - s_i) (linear, so the bias
        cancels), and W^f W^z is one 9 x hidden map, so each pair costs a 9-wide product instead of a 9- and a
        hidden-wide one (STAF Sec. 3's phi, the same function to float rounding; the pairs are most of the network's
        work: docs/staf_planned.md, printed vs used, row 3). `pair_map`: that map computed beforehand (`frozen_act`)."""
        msg = diff @ (self._pair_map() if pair_map is None else pair_map)
        if self.cfg.message == "relu":
            msg = torch.relu(msg + self.b_msg)
        return msg

    def embed(
        self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor, pair_map: torch.Tensor | None = None
    ) -> torch.Tensor:
        """f (.., n, hidden): own (.., n, 6, or 7 with `drive_input`), edge (.., n, n, 9), mask (.., n, n)."""
        z = self._own_embedding(own)
        return self.w_f(z) + (self._message(edge, pair_map) * mask[..., None].float()).sum(-2)

    def embed_sparse(self, own: torch.Tensor, receiver: torch.Tensor, diff: torch.Tensor) -> torch.Tensor:
        """`embed` on an edge list, for large teams: own (n, 6), receiver (E,) = i of each pair, diff (E, 9) = s_j -
        s_i."""
        z = self._own_embedding(own)
        return self.w_f(z).index_add(0, receiver, self._message(diff))

    def _mean(self, f: torch.Tensor, own: torch.Tensor) -> torch.Tensor:
        mean = self.psi(f)
        if self.cfg.prior_gain > 0:  # residual on a proportional step to the target (docs/staf_planned.md, decision 5)
            mean = mean + proportional_step(own, self.cfg.prior_gain)
        return mean

    def act(
        self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor, pair_map: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Action means (.., n, 2) without the critic: execution only."""
        return self._mean(self.embed(own, edge, mask, pair_map), own)

    def frozen_act(self) -> Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]:
        """`act` for weights that no longer change (a controller's loaded checkpoint): the pair map and the weights'
        slices are taken once, and the layers are called as plain functions, not modules (a tenth of the network's
        time at ten robots: benchmarks/staf_decision_time.py); the same products in the same order, so the same bits
        (a test)."""
        with torch.no_grad():
            pair_map = self._pair_map()
            own_map = self.w_z.weight[:, 2 : 2 + STAF_OWN].T
            own_const = self.w_z.weight[:, 2 + STAF_OWN]
            first, last = self.psi[0], self.psi[2]
            assert isinstance(first, nn.Linear) and isinstance(last, nn.Linear)
        cfg, linear = self.cfg, nn.functional.linear

        def act(own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
            z = own[..., :STAF_OWN] @ own_map + own_const + self.b_z  # _own_embedding
            if cfg.drive_input:
                z = z + own[..., STAF_OWN : STAF_OWN + 1] * self.w_drive
            msg = edge @ pair_map  # _message
            if cfg.message == "relu":
                msg = torch.relu(msg + self.b_msg)
            f = linear(z, self.w_f.weight) + (msg * mask[..., None].float()).sum(-2)  # embed
            mean = linear(torch.relu(linear(f, first.weight, first.bias)), last.weight, last.bias)  # psi
            if cfg.prior_gain > 0:
                mean = mean + proportional_step(own, cfg.prior_gain)
            return mean

        return act

    def act_sparse(self, own: torch.Tensor, receiver: torch.Tensor, diff: torch.Tensor) -> torch.Tensor:
        """Action means (n, 2) from an edge list (no critic: execution only)."""
        return self._mean(self.embed_sparse(own, receiver, diff), own)

    def forward(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Action mean (.., n, 2) and value (.., n)."""
        f = self.embed(own, edge, mask)
        team = f.mean(dim=-2, keepdim=True).expand_as(f)
        return self._mean(f, own), self.critic(torch.cat([f, team], dim=-1))[..., 0]
