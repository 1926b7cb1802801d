"""`stafpipe export`: a learned network as an ONNX file a robot can run without torch or stafpipe (docs/export.md).

Four networks, one team (one world) per call, any number of robots (the `robots` axis is dynamic):
- `staf`, `staf_planned`: the intermediate GNN phi and low level psi (STAF, Sec. 3) of the paper's STAF and of
  STAF-planned (ours): own (n, 6), edge (n, n, 9), mask (n, n) -> action (n, 2), the mean action a_i = psi(f_i)
  (learning/staf_net.py); the same network, trained under other rules.
- `dgnn`: the DGNN baseline's policy (Blumenkamp et al., ICRA 2022): own (n, 7), edge (n, n, 5), mask (n, n) ->
  action (n, 2) (methods/dgnn/network.py).
- `high`: STAF's deep graph cut (Sec. 3): x (n, F), adjacency (n, n), m () -> assignment (n, m_max), the soft
  subteam assignment Y whose row argmax is each robot's subteam (highlevel/model.py), in the dense form.
Only the deterministic parts are exported: no critic, no sampling. The file's metadata carries the checkpoint's
`made_by` record and the input layout, so a user can tell which training run a file came from.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import nn

from stafpipe.errors import StafpipeError
from stafpipe.highlevel.model import DeepGraphCut
from stafpipe.io import atomic_write
from stafpipe.learning.policy_net import PolicyNet
from stafpipe.registry import adapter_class, learned_methods

log = logging.getLogger(__name__)
OPSET = 18
HIGH = "high"
"""The deep graph cut's name among the exportable networks (every learned method's policy, and this)."""


def networks() -> list[str]:
    """What `stafpipe export` can write: every learned method's policy (the registry's) and the deep graph cut."""
    return [*learned_methods(), HIGH]


class PolicyMean(nn.Module):
    """The execution part of a learned policy: action means (n, 2) of one team; with more training runs of the
    network (`method.ensemble`), the mean of their action means, as the eval controller acts."""

    def __init__(self, policy: PolicyNet, *members: PolicyNet):
        super().__init__()
        self.policy = policy
        self.members = nn.ModuleList(members)

    def forward(self, own: torch.Tensor, edge: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        mean = self.policy.act(own, edge, mask)
        if len(self.members):
            means = [mean, *(m.act(own, edge, mask) for m in self.members)]  # type: ignore[operator]
            mean = torch.stack(means).mean(0)
        return mean


class DenseGraphCut(nn.Module):
    """DeepGraphCut's forward pass for one team on a dense adjacency (as NumpyGraphCut computes it), with the same
    weights: attention over j with adjacency[i, j] (j sends to i), heads averaged, tau on [h || one_hot(m)]."""

    def __init__(self, model: DeepGraphCut):
        super().__init__()
        self.model = model

    def forward(self, x: torch.Tensor, adjacency: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
        cfg, model = self.model.cfg, self.model
        n = x.shape[0]
        h = model.w_v(x)
        layers: list[Any] = list(model.layers)  # AttentionLayer modules
        for k, layer in enumerate(layers):
            wa = layer.w_a(h).view(n, cfg.heads, cfg.hidden)
            s_i = (wa * layer.a[:, : cfg.hidden]).sum(-1).T  # (H, n)
            s_j = (wa * layer.a[:, cfg.hidden :]).sum(-1).T
            scores = layer.act(s_i[:, :, None] + s_j[:, None, :])  # (H, i, j)
            scores = scores.masked_fill(~adjacency[None], -torch.inf)
            # a robot without neighbours: all -inf -> its alpha row is 0 (as the sparse form's empty sum)
            peak = scores.amax(-1, keepdim=True).clamp_min(-1e30)
            e = torch.exp(scores - peak)
            alpha = e / e.sum(-1, keepdim=True).clamp_min(1e-30)
            wh = layer.w_h(h).view(n, cfg.heads, cfg.hidden).transpose(0, 1)  # (H, n, W)
            h = (wh + alpha @ wh).mean(0)
            if k + 1 < len(layers):
                h = torch.relu(h)
        slots = torch.arange(cfg.m_max)
        one_hot = (slots == m - 1).to(x.dtype).expand(n, cfg.m_max)
        logits = model.tau(torch.cat([h, one_hot], dim=1))
        return torch.softmax(logits.masked_fill(slots[None, :] >= m, -torch.inf), dim=1)


def example_inputs(network: str, module: Any, n: int = 5) -> dict[str, torch.Tensor]:
    """Inputs of the right shapes and types for `network` (random values; a team of n robots)."""
    gen = torch.Generator().manual_seed(0)
    if network == HIGH:
        cfg = module.model.cfg
        adjacency = torch.rand(n, n, generator=gen) < 0.6
        adjacency = (adjacency | adjacency.T) & ~torch.eye(n, dtype=torch.bool)
        return {
            "x": torch.randn(n, 2 * len(cfg.features), generator=gen),
            "adjacency": adjacency,
            "m": torch.tensor(min(2, cfg.m_max), dtype=torch.int64),
        }
    net = adapter_class(network).network
    if net.own_features is None or net.edge_features is None:
        raise StafpipeError(f"export: {network}'s network {net.__name__} does not declare its input widths")
    own = net.own_features + int(module.policy.cfg.drive_input and net.reads_drive_flag)
    edge = net.edge_features
    mask = (torch.rand(n, n, generator=gen) < 0.6) & ~torch.eye(n, dtype=torch.bool)
    return {
        "own": torch.randn(n, own, generator=gen),
        "edge": torch.randn(n, n, edge, generator=gen) * mask[..., None],
        "mask": mask,
    }


def load_network(network: str, checkpoint: str = "", ensemble: list[str] | None = None) -> tuple[nn.Module, dict]:
    """The exportable module of `network` from `checkpoint` (empty: the shipped one) and the checkpoint's record. A
    policy comes with the runs `ensemble` names, by the eval controller's rule (`ensemble_paths`: unset, the shipped
    partners of the shipped checkpoint), so the file acts as `stafpipe eval` does; the record then lists every run's
    under `ensemble`."""
    if network not in networks():
        raise StafpipeError(f"export: network must be one of {networks()}, got {network!r}")
    if network == HIGH:
        from stafpipe.highlevel.checkpoint import load_checkpoint

        if ensemble:
            raise StafpipeError("export: --ensemble is for policies (staf, staf_planned, dgnn), not the deep graph cut")
        model, made_by = load_checkpoint(checkpoint)
        return DenseGraphCut(model).eval(), made_by
    from stafpipe.learning.checkpoint import ensemble_paths, load_members, load_policy

    policy, made_by = load_policy(checkpoint, network)
    paths = ensemble_paths(checkpoint, ensemble, network)
    members = load_members(paths, policy, network, "export: ensemble")
    if members:
        made_by = {**made_by, "ensemble": [{"path": path, "made_by": record} for path, _, record in members]}
    return PolicyMean(policy, *(member for _, member, _ in members)).eval(), made_by


def export(network: str, checkpoint: str, out: Path, ensemble: list[str] | None = None) -> Path:
    """Write `network` of `checkpoint` (with `ensemble`, as `load_network` reads it) to `out` as ONNX (atomically),
    with a dynamic robot count."""
    import onnx  # the `onnx` extra: onnx, onnxscript (torch's exporter)

    module, made_by = load_network(network, checkpoint, ensemble)
    inputs = example_inputs(network, module)
    robots = torch.export.Dim("robots", min=2, max=4096)
    shapes = {
        name: (
            {0: robots}
            if value.dim() == 2 and name in ("own", "x")
            else {0: robots, 1: robots}
            if value.dim() >= 2
            else {}
        )
        for name, value in inputs.items()
    }
    output = "assignment" if network == HIGH else "action"

    def write(tmp: Path) -> None:
        quiet = logging.getLogger("torch.onnx")
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        try:  # the exporter's progress lines, notes on axis names and deprecations: not ours to show
            with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
                warnings.simplefilter("ignore")
                program = torch.onnx.export(
                    module,
                    tuple(inputs.values()),
                    dynamo=True,
                    input_names=list(inputs),
                    output_names=[output],
                    dynamic_shapes=shapes,
                    opset_version=OPSET,
                    verbose=False,
                )
        finally:
            quiet.setLevel(level)
        assert program is not None  # dynamo=True returns the program
        model = program.model_proto
        meta = {
            "stafpipe.network": network,
            "stafpipe.checkpoint": checkpoint or "shipped",
            "stafpipe.made_by": json.dumps(made_by, sort_keys=True, default=str),
        }
        for key, value in meta.items():
            entry = model.metadata_props.add()
            entry.key, entry.value = key, value
        onnx.checker.check_model(model)
        onnx.save(model, str(tmp))

    try:
        return atomic_write(out, write)
    except OSError as exc:
        raise StafpipeError(f"export: cannot write {out}: {exc.strerror or exc}") from None
