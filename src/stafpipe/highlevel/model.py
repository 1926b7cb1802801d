"""The deep graph cut network of STAF's high level (STAF, Section 3 and Appendix C).

Embedding omega (a graph attention network, [54] = GAT):
  m_i = W^v p_i                                          (Section 3; Appendix C: W^v is 2 x 32)
  alpha_ij = softmax_{j in N(i)} ReLU(a^T [W^a m_i || W^a m_j])   (Section 3; printed without `a`, see docs/method.md)
  h_i = W^h m_i + sum_{j in N(i)} alpha_ij W^h m_j       (Section 3; Appendix C: W^a, W^h are 32 x 32, three layers)
  with several heads per layer, averaged (the "multi-head mechanism [54]").
Classifier tau: two linear layers and a softmax -> Y (n x m) (Section 3). Ours also sees m (one-hot), so that one
network serves every m up to `m_max`; logits of subteams >= m are masked out.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from stafpipe.highlevel.config import HighLevelConfig
from stafpipe.highlevel.graphs import TeamBatch


def scatter_softmax(scores: torch.Tensor, index: torch.Tensor, size: int) -> torch.Tensor:
    """Softmax of `scores` (E, H) over the entries that share an `index` (E,) (the neighbours of one node)."""
    idx = index[:, None].expand_as(scores)
    peak = torch.full((size, scores.shape[1]), -torch.inf, dtype=scores.dtype, device=scores.device).scatter_reduce(
        0, idx, scores, reduce="amax", include_self=True
    )
    e = torch.exp(scores - peak[index])
    total = torch.zeros((size, scores.shape[1]), dtype=scores.dtype, device=scores.device).index_add_(0, index, e)
    return e / total[index]


class AttentionLayer(nn.Module):
    """One STAF attention layer with `heads` heads (Section 3), on a disjoint edge-list graph."""

    def __init__(self, width: int, heads: int, attention: str):
        super().__init__()
        self.heads, self.width = heads, width
        self.w_a = nn.Linear(width, width * heads, bias=False)  # W^a per head
        self.a = nn.Parameter(torch.empty(heads, 2 * width))  # scores [W^a m_i || W^a m_j] -> scalar (GAT's a)
        self.w_h = nn.Linear(width, width * heads, bias=False)  # W^h per head
        self.act = nn.ReLU() if attention == "relu" else nn.LeakyReLU(0.2)
        nn.init.xavier_uniform_(self.a)

    def forward(self, m: torch.Tensor, edges: torch.Tensor) -> torch.Tensor:
        n, h, w = m.shape[0], self.heads, self.width
        src, dst = edges  # message j=src -> i=dst
        wa = self.w_a(m).view(n, h, w)
        # a^T [W^a m_i || W^a m_j] = a_1^T W^a m_i + a_2^T W^a m_j, computed per node, then gathered per edge.
        s_i = (wa * self.a[:, :w]).sum(-1)
        s_j = (wa * self.a[:, w:]).sum(-1)
        alpha = scatter_softmax(self.act(s_i[dst] + s_j[src]), dst, n)  # (E, H)
        wh = self.w_h(m).view(n, h, w)
        agg = torch.zeros_like(wh).index_add_(0, dst, alpha[..., None] * wh[src])
        return (wh + agg).mean(dim=1)  # h_i = W^h m_i + sum_j alpha_ij W^h m_j, heads averaged


class DeepGraphCut(nn.Module):
    """omega (attention embedding) followed by tau (classifier): node features -> Y (N, m_max), rows softmax over m."""

    def __init__(self, cfg: HighLevelConfig):
        super().__init__()
        self.cfg = cfg
        in_dim = 2 * len(cfg.features)
        self.w_v = nn.Linear(in_dim, cfg.hidden)  # m_i = W^v p_i (Section 3)
        self.layers = nn.ModuleList(AttentionLayer(cfg.hidden, cfg.heads, cfg.attention) for _ in range(cfg.layers))
        self.tau = nn.Sequential(  # two linear layers + softmax (Section 3); m enters as a one-hot
            nn.Linear(cfg.hidden + cfg.m_max, cfg.hidden), nn.ReLU(), nn.Linear(cfg.hidden, cfg.m_max)
        )

    def embed(self, batch: TeamBatch) -> torch.Tensor:
        """H = omega(G): (N, hidden) node embeddings."""
        h = self.w_v(batch.x)
        for k, layer in enumerate(self.layers):
            h = layer(h, batch.edges)
            if k + 1 < len(self.layers):
                h = torch.relu(h)  # between layers, as in GAT; the paper names none
        return h

    def forward(self, batch: TeamBatch) -> torch.Tensor:
        """Y: (N, m_max) subteam probabilities; columns >= the node's team m are exactly 0."""
        h = self.embed(batch)
        m_node = batch.m[batch.team]
        one_hot = nn.functional.one_hot(m_node - 1, self.cfg.m_max).float()
        logits = self.tau(torch.cat([h, one_hot], dim=1))
        allowed = torch.arange(self.cfg.m_max, device=m_node.device)[None, :] < m_node[:, None]
        return torch.softmax(logits.masked_fill(~allowed, -torch.inf), dim=1)


class NumpyGraphCut:
    """The same forward pass in numpy with dense attention, for deciding one small team fast (torch's per-op overhead
    dominates below ~100 robots: measured on the 2-core development machine). Fewer, larger products, the same
    function to float rounding (the decision step's cost, benchmarks/staf_decision_time.py): each layer's three
    products with h (W^h, and W^a followed by a's two halves: a^T W^a m is linear in m) are one product with their
    weights side by side; W^v is folded into the first layer's (m_i = W^v p_i enters only through it); the heads'
    mean's 1/H into the next layer's (ReLU(h / H) = ReLU(h) / H) or tau's; and the one-hot of m picks a row of tau's
    first weights. A test checks it equals DeepGraphCut's output."""

    def __init__(self, model: DeepGraphCut):
        self.cfg = model.cfg
        heads, width = self.cfg.heads, self.cfg.hidden
        w = {k: v.detach().numpy().astype(np.float64) for k, v in model.state_dict().items()}
        self.layers: list[np.ndarray] = []
        for k in range(self.cfg.layers):
            w_a = w[f"layers.{k}.w_a.weight"].T.reshape(width, heads, width)  # (in, head, out)
            a = w[f"layers.{k}.a"]
            score_i = np.einsum("khw,hw->kh", w_a, a[:, :width])  # m -> a_1^T W^a m, per head
            score_j = np.einsum("khw,hw->kh", w_a, a[:, width:])
            fused = np.concatenate([w[f"layers.{k}.w_h.weight"].T, score_i, score_j], axis=1)
            self.layers.append(fused / heads if k else fused)
        w_v, b_v = w["w_v.weight"].T, w["w_v.bias"]
        self.first_bias = b_v @ self.layers[0]
        self.layers[0] = w_v @ self.layers[0]
        w0, b0 = w["tau.0.weight"].T, w["tau.0.bias"]
        self.tau_h = w0[:width] / heads
        self.tau_m = w0[width:] + b0  # row m - 1: the one-hot of m's product, with the bias
        self.tau_out = (w["tau.2.weight"].T, w["tau.2.bias"])

    def __call__(self, x: np.ndarray, edges: np.ndarray, m: int, adj: np.ndarray | None = None) -> np.ndarray:
        """Y (n, m_max) for one team: node features x (n, F), directed edges (2, E); or `adj` (n, n) bool, adj[i, j]:
        j sends to i, in place of the edges."""
        return softmax_rows(self.logits(x, edges, m, adj), m)

    def logits(self, x: np.ndarray, edges: np.ndarray, m: int, adj: np.ndarray | None = None) -> np.ndarray:
        """tau's logits (n, m_max) before the softmax (its argmax over the first m columns is Y's)."""
        n, heads, width = len(x), self.cfg.heads, self.cfg.hidden
        if adj is None:
            adj = np.zeros((n, n), dtype=bool)
            adj[edges[1], edges[0]] = True
        # ufuncs' reduce in place of the array methods: the same values without the methods' wrappers (the plan's
        # split calls this within a control step: benchmarks/staf_decision_time.py)
        lonely = not np.logical_or.reduce(adj, axis=1).all()  # a robot with no neighbour: its sum over neighbours is 0
        mask = np.where(adj, 0.0, -np.inf)
        split = heads * width
        h = x
        for k, fused in enumerate(self.layers):  # in place where it can be: each array is a step's own
            z = h @ fused
            if k == 0:
                z += self.first_bias
            wh = z[:, :split].reshape(n, heads, width).transpose(1, 0, 2)  # (H, n, W)
            scores = z[:, split : split + heads].T[:, :, None] + z[:, split + heads :].T[:, None, :]  # (H, i, j)
            np.maximum(scores, 0.0 if self.cfg.attention == "relu" else 0.2 * scores, out=scores)
            scores += mask
            peak = np.maximum.reduce(scores, axis=2, keepdims=True)
            if lonely:
                peak = np.where(np.isfinite(peak), peak, 0.0)
            scores -= peak
            alpha = np.exp(scores, out=scores)
            total = np.add.reduce(alpha, axis=2, keepdims=True)
            alpha /= np.maximum(total, 1e-300) if lonely else total
            agg = alpha @ wh
            agg += wh
            h = np.add.reduce(agg, axis=0)  # H x the heads' mean: 1/H is in the next weights
            if k + 1 < len(self.layers):
                np.maximum(h, 0.0, out=h)
        w1, b1 = self.tau_out
        return np.maximum(h @ self.tau_h + self.tau_m[m - 1], 0.0) @ w1 + b1


def softmax_rows(logits: np.ndarray, m: int) -> np.ndarray:
    """Y (n, m_max) from tau's logits: a softmax over each row's first m columns, the others exactly 0."""
    logits = logits.copy()
    logits[:, m:] = -np.inf
    e = np.exp(logits - logits.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)
