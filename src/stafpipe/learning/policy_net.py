"""What every learned method's network offers the trainer, the controller and the exporter (one interface, so the
trainer has no method-name branches): a Gaussian policy over velocity commands with a value head."""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import torch
from torch import nn

from stafpipe.learning.config import PolicyConfig


class PolicyNet(nn.Module):
    """Base of DGNNPolicy and StafPolicy: `forward` gives the action mean (.., n, 2) and the value (.., n) from own
    (.., n, F), edge (.., n, n, E) and mask (.., n, n); `act` the mean alone; `distribution` the Gaussian around a
    mean with the learned, state-independent standard deviation."""

    cfg: PolicyConfig
    log_std: nn.Parameter
    reads_drive_flag: ClassVar[bool] = False
    """Whether the network takes `policy.drive_input`'s differential-drive flag in its own state."""
    own_features: ClassVar[int | None] = None
    edge_features: ClassVar[int | None] = None
    """Widths of a robot's own state (without the drive flag) and of a pair's edge features (`learning/features.py`):
    what `stafpipe export` builds example inputs from; a network that leaves them None is not exported."""

    def act(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def frozen_act(self) -> Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]:
        """`act` for weights that will not change again (a controller's loaded checkpoint), with whatever can be
        computed from the weights alone computed once; the same outputs to the bit. Training never uses it."""
        return self.act

    def forward(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        raise NotImplementedError

    def distribution(self, mean: torch.Tensor, validate: bool = True) -> torch.distributions.Normal:
        """`validate` false skips torch's argument checks (a NaN mean): each check waits for a GPU, so the update,
        which checks its losses itself, leaves them out."""
        return torch.distributions.Normal(mean, self.log_std.exp().expand_as(mean), validate_args=validate)
