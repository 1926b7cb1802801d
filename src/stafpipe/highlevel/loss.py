"""STAF's unsupervised subteaming loss, Eq. (1) (STAF, Section 3), per team of a batch.

  L_st = Y(1 - Y)^T E + sum_j (sum_i y_ij - n/m) + sum_j || sum_i y_ij p_i / sum_i y_ij - sum_i y_ij g_i / sum_i y_ij ||

As printed, the first term is an n x n matrix and the second is identically 0 for softmax rows; docs/method.md writes
the printed and the used form side by side. Used (each term scaled to be comparable across team sizes):
  adjacency  trace(Y (1 - Y)^T E) / sum(E): the expected fraction of radius-graph edges cut
  balance    sum_{j<m} (sum_i y_ij - n/m)^2 / (n^2 (m - 1) / m): 0 when balanced, 1 with everyone in one subteam
  goal       sum_{j<m} (n_j / n) || c^p_j - c^g_j || / || p_bar - g_bar ||, n_j = sum_i y_ij: the size-weighted
             subteam-to-goal centre distance, 1 for the whole team. Unweighted as printed, a soft cut lowers the sum by
             emptying subteams (we measured 1.0 -> 0.73 with m <= 4), which is not its intent.
"""

from __future__ import annotations

import torch

from stafpipe.highlevel.config import LossWeights
from stafpipe.highlevel.graphs import TeamBatch

TERMS = ("adjacency", "balance", "goal")


def subteam_sums(y: torch.Tensor, batch: TeamBatch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per team and subteam: soft sizes sum_i y_ij (T, M), sum_i y_ij p_i and sum_i y_ij g_i (T, M, 2)."""
    t, mm = len(batch.sizes), y.shape[1]
    on = y.device
    size = torch.zeros(t, mm, device=on).index_add_(0, batch.team, y)
    sp = torch.zeros(t, mm, 2, device=on).index_add_(0, batch.team, y[:, :, None] * batch.pos[:, None, :])
    sg = torch.zeros(t, mm, 2, device=on).index_add_(0, batch.team, y[:, :, None] * batch.goal[:, None, :])
    return size, sp, sg


def loss_terms(y: torch.Tensor, batch: TeamBatch) -> dict[str, torch.Tensor]:
    """The three terms of Eq. (1) as used (module docstring), each (T,) per team."""
    t, mm = len(batch.sizes), y.shape[1]
    n = batch.sizes.float()
    m = batch.m.float()
    src, dst = batch.edges
    # adjacency: [Y (1 - Y)^T]_ik = sum_j y_ij (1 - y_kj) = 1 - sum_j y_ij y_kj for softmax rows (pair in different
    # subteams)
    cut = 1.0 - (y[src] * y[dst]).sum(dim=1)
    edge_team = batch.team[dst]
    cut_sum = torch.zeros(t, device=y.device).index_add_(0, edge_team, cut)
    edge_count = torch.zeros(t, device=y.device).index_add_(0, edge_team, torch.ones_like(cut))
    adjacency = cut_sum / edge_count.clamp_min(1.0)
    size, sp, sg = subteam_sums(y, batch)
    valid = torch.arange(mm, device=y.device)[None, :] < batch.m[:, None]
    dev = ((size - (n / m)[:, None]) ** 2 * valid).sum(dim=1)
    balance = torch.where(m > 1, dev / (n**2 * (m - 1) / m).clamp_min(1e-9), torch.zeros_like(dev))
    # n_j || c^p_j - c^g_j || = || sum_i y_ij (p_i - g_i) ||
    weighted_gap = torch.linalg.vector_norm(sp - sg, dim=2)
    p_bar = torch.zeros(t, 2, device=y.device).index_add_(0, batch.team, batch.pos) / n[:, None]
    g_bar = torch.zeros(t, 2, device=y.device).index_add_(0, batch.team, batch.goal) / n[:, None]
    scale = (n * torch.linalg.vector_norm(p_bar - g_bar, dim=1)).clamp_min(1e-6)
    goal = (weighted_gap * valid).sum(dim=1) / scale
    return {"adjacency": adjacency, "balance": balance, "goal": goal}


def balance_printed(y: torch.Tensor, batch: TeamBatch) -> torch.Tensor:
    """The balance term exactly as printed in Eq. (1), per team: sum_j (sum_i y_ij - n/m). Identically 0 (method.md)."""
    size, _, _ = subteam_sums(y, batch)
    valid = torch.arange(y.shape[1], device=y.device)[None, :] < batch.m[:, None]
    return ((size - (batch.sizes.float() / batch.m.float())[:, None]) * valid).sum(dim=1)


def total_loss(terms: dict[str, torch.Tensor], w: LossWeights) -> torch.Tensor:
    """Weighted sum of the terms, averaged over the teams of the batch."""
    return (w.adjacency * terms["adjacency"] + w.balance * terms["balance"] + w.goal * terms["goal"]).mean()
