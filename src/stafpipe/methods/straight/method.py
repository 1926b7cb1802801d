"""`method=straight`: every robot drives straight to its own goal slot. A test fixture for the harness, not a
baseline."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stafpipe.controllers.base import Controller
from stafpipe.sensing import Observation


@dataclass
class StraightConfig:
    """Config of `method=straight` (group `method`)."""

    name: str = "straight"
    gain: float = 1.5
    """Proportional gain (1/s) near the goal; the drive caps the speed."""


class StraightController(Controller):
    """Velocity = gain x (goal - position)."""

    def __init__(self, cfg: StraightConfig) -> None:
        super().__init__()
        self.cfg = cfg

    def act(self, obs: Observation) -> np.ndarray:
        return self.cfg.gain * (obs.goal - obs.position)
