"""The DGNN policy (Blumenkamp, Morad, Gielis, Li, Prorok, ICRA 2022): a decentralized GNN over neighbours within the
communication radius feeding an MLP actor, with parameters shared by all robots. Dense over the n robots of a world
(n is small); masks cut the graph to the communication radius, and on the CPU the messages are computed for the
pairs within it alone."""

from __future__ import annotations

import torch
from torch import nn

from stafpipe.learning.config import PolicyConfig
from stafpipe.learning.features import EDGE, OWN
from stafpipe.learning.policy_net import PolicyNet


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for k in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[k], sizes[k + 1]))
        if k + 2 < len(sizes):
            layers.append(
                nn.ReLU()
            )  # ReLU, not tanh: 4x faster on this torch build (measured on the 2-core development machine)
    return nn.Sequential(*layers)


class DGNNPolicy(PolicyNet):
    """Gaussian policy over planar velocity commands (in the robot's frame, scaled by max speed) and a value per
    robot."""

    own_features, edge_features = OWN, EDGE

    def __init__(self, cfg: PolicyConfig):
        super().__init__()
        h = cfg.hidden
        self.cfg = cfg
        self.encoder = _mlp([OWN, h, h])
        # message MLP on [e_j || edge_ij]; its first layer is split into a per-sender and a per-edge part, which is the
        # same linear map computed without repeating e_j for every receiver (the update's cost is in these pairs)
        self.msg_sender = nn.ModuleList(nn.Linear(h, h) for _ in range(cfg.message_layers))
        self.msg_edge = nn.ModuleList(nn.Linear(EDGE, h, bias=False) for _ in range(cfg.message_layers))
        self.msg_out = nn.ModuleList(nn.Linear(h, h) for _ in range(cfg.message_layers))
        self.updates = nn.ModuleList(_mlp([2 * h, h]) for _ in range(cfg.message_layers))
        self.actor = _mlp([h, h, 2])
        self.critic = _mlp([2 * h, h, 1])  # own features + team mean: a centralized critic (allowed by the issue)
        self.log_std = nn.Parameter(torch.full((2,), cfg.init_log_std))

    def trunk(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """(.., n, hidden) embeddings after message passing: own (.., n, 7), edge (.., n, n, 5), mask (.., n, n). On
        the CPU the messages are computed for the mask's pairs alone (`_trunk_edges`); on another device, and while
        exported to ONNX, for every pair and masked (`_trunk_dense`): the same function (a test compares them)."""
        if own.device.type == "cpu" and not torch.onnx.is_in_onnx_export():
            return self._trunk_edges(own, edge, mask)
        return self._trunk_dense(own, edge, mask)

    def _trunk_dense(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        e = torch.relu(self.encoder(own))
        w = mask.float()
        count = w.sum(-1, keepdim=True).clamp_min(1.0)
        for k, update in enumerate(self.updates):
            pre = self.msg_sender[k](e)[..., None, :, :] + self.msg_edge[k](edge)  # [i, j]: from sender j to i
            m = torch.relu(self.msg_out[k](torch.relu(pre)))
            agg = (m * w[..., None]).sum(-2) / count  # mean over neighbours
            e = torch.relu(update(torch.cat([e, agg], dim=-1))) + e
        return e

    def _trunk_edges(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """`_trunk_dense` on the list of neighbour pairs: about 3 in 10 pairs of a training rollout are within the
        radius, and the pairs are most of the network's work, so the update costs a half to a third of the dense
        one on the CPU (docs/learning.md, "Messages over the neighbours alone"). The sum over a receiver's neighbours
        runs in the same order of j as the dense sum."""
        n, h = own.shape[-2], self.cfg.hidden
        e = torch.relu(self.encoder(own)).reshape(-1, h)  # (worlds x n, hidden)
        pairs = mask.reshape(-1, n, n)
        world, i, j = pairs.nonzero(as_tuple=True)  # row-major: j ascending within each receiver
        receiver, sender = world * n + i, world * n + j
        edge_list = edge.reshape(-1, n, n, edge.shape[-1])[world, i, j]
        count = pairs.sum(-1).reshape(-1, 1).clamp_min(1).to(e.dtype)
        for k, update in enumerate(self.updates):
            pre = self.msg_sender[k](e)[sender] + self.msg_edge[k](edge_list)
            m = torch.relu(self.msg_out[k](torch.relu(pre)))
            agg = torch.zeros_like(e).index_add(0, receiver, m) / count  # mean over neighbours
            e = torch.relu(update(torch.cat([e, agg], dim=-1))) + e
        return e.reshape(*own.shape[:-1], h)

    def act(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Action means (.., n, 2) without the critic: execution only."""
        return self.actor(self.trunk(own, edge, mask))

    def forward(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Action mean (.., n, 2) and value (.., n)."""
        e = self.trunk(own, edge, mask)
        team = e.mean(dim=-2, keepdim=True).expand_as(e)
        return self.actor(e), self.critic(torch.cat([e, team], dim=-1))[..., 0]
