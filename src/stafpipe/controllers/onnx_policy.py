"""`method=onnx`: any policy saved as ONNX, scored by our harness (metrics, MCAP logs, tables) on our maps. Its input is
the observation `stafpipe.marl_env` gives (docs/marl_env.md) with that environment's default feature settings, and
its output each robot's action as the environment takes it (a robot-frame velocity in units of the robot's top
speed, clipped to [-1, 1]); a policy trained on the environment, in any library, runs here as it was trained. Two
input layouts are accepted, told apart by the model's input names:
- `own` (n, F), `edge` (n, n, E), `mask` (n, n): one team per call (what `stafpipe export` writes);
- one input (n, F + n (E + 1)): every robot's flattened row, as the PettingZoo form gives each agent.
The output is (n, 2), or (1, n, 2). `method.features` names whose features these are (`dgnn`, `staf_planned`, `staf`:
the learned method whose adapter computes them, with its targets and subteams)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from stafpipe.config.checks import check_sensing_radius
from stafpipe.controllers.base import Controller
from stafpipe.controllers.learned import LearnedController
from stafpipe.errors import StafpipeError, require
from stafpipe.learning.config import PolicyConfig, RewardConfig
from stafpipe.learning.features import flat_rows
from stafpipe.registry import adapter_class, learned_methods


@dataclass
class OnnxConfig:
    """Config of `method=onnx` (group `method`)."""

    name: str = "onnx"
    model: str = ""
    """The .onnx file (required)."""
    features: str = "dgnn"
    """Whose observation the model takes: `dgnn` (own 7, edge 5), `staf_planned` or `staf` (own 6, edge 9)."""
    sensing_radius: float = 2.0
    """The radius the observation clips what a robot senses at; must equal the run's `sensing.radius`."""
    allow_mismatch: bool = False
    """Run with `sensing_radius` other than the run's `sensing.radius` anyway."""
    approach_cap: bool = False
    """The safety layer of the learned methods (the approach speed capped near robots and walls); off: the policy
    acts alone."""
    approach_cap_gap: float = 0.02
    """approach_cap: the gap (m) it brakes to."""
    avoid_movers: bool = False
    """Moving obstacles avoided by the learned methods' safety layer (controllers/orca.py); off: the policy alone."""
    deterministic: bool = True
    """The model's output is taken as the action (an ONNX policy exports its mean; sampling is not offered)."""

    def check(self, key: str = "method") -> None:
        require(bool(self.model), f"{key}.model", "is required: the .onnx file of the policy", self.model)
        path = Path(self.model)
        if path.is_dir():
            raise StafpipeError(f"{key}.model: {path} is a directory, not an ONNX file")
        require(path.is_file(), f"{key}.model", "must name an existing file", self.model)
        learned = learned_methods()
        require(self.features in learned, f"{key}.features", f"must be one of {learned}", self.features)
        require(self.deterministic, f"{key}.deterministic", "must be true (the model gives the action itself)", False)
        require(self.approach_cap_gap >= 0, f"{key}.approach_cap_gap", "must be >= 0", self.approach_cap_gap)

    def check_run(self, sensing: Any, world: Any, key: str = "method") -> None:
        check_sensing_radius(self.sensing_radius, sensing.radius, self.allow_mismatch, key)


def _said(exc: BaseException) -> str:
    """The first line of what onnxruntime said, or the exception's kind where it said nothing."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


class OnnxPolicy:
    """An ONNX policy on one thread (onnxruntime), called as the learned controller calls a network: (1, n, F),
    (1, n, n, E), (1, n, n) tensors -> (1, n, 2)."""

    GRAPH = ("own", "edge", "mask")

    def __init__(self, path: str) -> None:
        import onnxruntime as ort  # the `onnx` extra

        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1  # as the torch networks: the seed fixes it
        try:
            self.session = ort.InferenceSession(path, options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # noqa: BLE001 (onnxruntime raises its own kinds for a file it cannot load)
            raise StafpipeError(
                f"method.model: {path} is not an ONNX model onnxruntime can load ({_said(exc)})"
            ) from None
        self.inputs = [i.name for i in self.session.get_inputs()]
        types = {"tensor(bool)": np.bool_, "tensor(double)": np.float64, "tensor(float16)": np.float16}
        self.dtypes = {i.name: types.get(i.type, np.float32) for i in self.session.get_inputs()}
        if set(self.GRAPH) <= set(self.inputs):
            self.layout = "graph"
        elif len(self.inputs) == 1:
            self.layout = "flat"
        else:
            raise StafpipeError(
                f"method.model: {path} takes inputs {self.inputs}; expected own, edge, mask (one team) or one "
                "input of every robot's flattened observation (docs/marl_env.md)"
            )
        self.output = self.session.get_outputs()[0].name

    def __call__(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        o, e, m = (x[0].numpy().astype(np.float32) for x in (own, edge, mask))
        if self.layout == "graph":
            feed = dict(zip(self.GRAPH, (o, e, m), strict=True))
        else:
            feed = {self.inputs[0]: flat_rows(o, e, m)}
        feed = {k: v.astype(self.dtypes[k]) for k, v in feed.items()}
        try:
            (action,) = self.session.run([self.output], feed)
        except Exception as exc:  # noqa: BLE001 (onnxruntime's own kinds: wrong shapes, types, ranks)
            shapes = {k: v.shape for k, v in feed.items()}
            raise StafpipeError(f"method.model: the model refused the observation {shapes} ({_said(exc)})") from None
        action = np.asarray(action, dtype=np.float32).reshape(-1, 2)
        if action.shape[0] != o.shape[0] or not np.isfinite(action).all():
            what = "non-finite actions" if action.shape[0] == o.shape[0] else f"actions of shape {action.shape}"
            raise StafpipeError(f"method.model: the model gave {what} for {o.shape[0]} robots; it must give (n, 2)")
        return torch.from_numpy(np.clip(action, -1.0, 1.0))[None]


class OnnxController(LearnedController):
    """The ONNX policy for every robot of a batch of worlds, through the adapter of `method.features`."""

    def __init__(self, cfg: OnnxConfig) -> None:
        # no checkpoint to load: LearnedController's own set-up is replaced by the model's
        Controller.__init__(self)
        cfg.check()
        self.cfg = cfg
        self.teacher = "learned"
        self.made_by: dict[str, Any] = {}
        self._acts = [OnnxPolicy(cfg.model)]
        self.trained_speed = math.inf  # actions are fractions of the robot's own top speed, as the environment's
        # the features with marl_env's default settings, as the policy saw them in the environment
        self._set_up(adapter_class(cfg.features)(PolicyConfig(), RewardConfig(), None, cfg.sensing_radius))
