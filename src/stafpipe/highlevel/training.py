"""Training of the deep graph cut on synthetic teams (STAF Appendix B.1 and C), resumable after a kill.

STAF trains the high level "using ADMM as the optimization solver [68] by deriving the gradient of the unsupervised loss
function in Eq. (1)" (Appendix B.1). Ours uses Adam on the same gradient (docs/method.md says why); 100 epochs on 10,000
instances (Appendix C) are the defaults.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from stafpipe import __version__
from stafpipe.errors import StafpipeError
from stafpipe.highlevel.checkpoint import save_checkpoint
from stafpipe.highlevel.config import HighLevelConfig, LossWeights, TrainHighConfig
from stafpipe.highlevel.graphs import TeamGraph, collate
from stafpipe.highlevel.loss import TERMS, loss_terms, total_loss
from stafpipe.highlevel.model import DeepGraphCut
from stafpipe.progress import progress
from stafpipe.torch_io import save_payload, training_device
from stafpipe.training_record import commit

log = logging.getLogger(__name__)
STATE_FILE = "last.pt"


def _draw_m(rng: np.random.Generator, graphs: list[TeamGraph], choices: list[int]) -> list[int]:
    return [max(1, min(int(choices[rng.integers(len(choices))]), len(g.pos) - 1)) for g in graphs]


def evaluate(
    model: DeepGraphCut, graphs: list[TeamGraph], ms: list[int], w: LossWeights, batch_size: int = 512
) -> dict[str, float]:
    """Mean loss terms and weighted total over `graphs` (no gradient), on the model's device."""
    sums = dict.fromkeys([*TERMS, "total"], 0.0)
    device = next(model.parameters()).device
    with torch.no_grad():
        for start in range(0, len(graphs), batch_size):
            batch = collate(graphs[start : start + batch_size], ms[start : start + batch_size]).to(device)
            terms = loss_terms(model(batch), batch)
            for k in TERMS:
                sums[k] += float(terms[k].sum())
            sums["total"] += float(total_loss(terms, w)) * len(batch.sizes)
    return {k: v / max(len(graphs), 1) for k, v in sums.items()}


def train(
    graphs: list[TeamGraph],
    high: HighLevelConfig,
    tc: TrainHighConfig,
    seed: int,
    out_dir: Path,
    config_hash: str,
    made_by: dict[str, Any],
    on_epoch: Callable[[list[dict[str, float]]], None] | None = None,
) -> tuple[DeepGraphCut, list[dict[str, float]]]:
    """Train on `graphs`; after every epoch the whole state goes to `out_dir/last.pt`, so a rerun of the same config in
    the same directory continues where a killed one stopped and ends with the same weights as an uninterrupted run."""
    torch.set_num_threads(tc.threads)
    device = training_device(tc.device, "train_high.device")
    torch.manual_seed(seed)
    model = DeepGraphCut(high).to(device)  # initialised on the CPU (the same weights for a seed), then moved
    opt = torch.optim.Adam(model.parameters(), lr=tc.lr)
    n_val = int(round(len(graphs) * tc.val_fraction))
    train_set, val_set = graphs[n_val:], graphs[:n_val]
    if not train_set:
        raise StafpipeError(f"train_high: no training teams left after holding out {n_val} for validation")
    val_m = _draw_m(np.random.default_rng([seed, 1]), val_set, tc.m_choices)
    history: list[dict[str, float]] = []
    start_epoch = 0
    state_path = out_dir / STATE_FILE
    if state_path.is_file():
        state = torch.load(state_path, map_location="cpu", weights_only=True)
        if state.get("config_hash") == config_hash:
            model.load_state_dict(state["model"])
            opt.load_state_dict(state["optimizer"])  # (its state follows the parameters' device)
            history, start_epoch = state["history"], int(state["epoch"])
            log.info("resuming from epoch %d of %s", start_epoch, state_path)
        else:
            log.warning("%s was made by another config; starting afresh", state_path)
    steps = math.ceil(len(train_set) / tc.batch_size)
    for epoch in progress(
        range(start_epoch, tc.epochs), desc="train-high", unit="epoch", initial=start_epoch, total=tc.epochs
    ):
        rng = np.random.default_rng([seed, 2, epoch])  # the epoch's order and m draws depend on (seed, epoch) only
        order = rng.permutation(len(train_set))
        ms = _draw_m(rng, train_set, tc.m_choices)
        model.train()
        sums = dict.fromkeys([*TERMS, "total"], 0.0)
        for k in range(steps):
            idx = order[k * tc.batch_size : (k + 1) * tc.batch_size]
            batch = collate([train_set[i] for i in idx], [ms[i] for i in idx]).to(device)
            terms = loss_terms(model(batch), batch)
            loss = total_loss(terms, tc.loss)
            opt.zero_grad()
            loss.backward()
            opt.step()
            for name in TERMS:
                sums[name] += float(terms[name].detach().sum())
            sums["total"] += float(loss.detach()) * len(idx)
        model.eval()
        row = {"epoch": epoch + 1, **{f"train_{k}": v / len(train_set) for k, v in sums.items()}}
        if val_set:
            row.update({f"val_{k}": v for k, v in evaluate(model, val_set, val_m, tc.loss).items()})
        history.append(row)
        state = {
            "config_hash": config_hash,
            "epoch": epoch + 1,
            "model": model.state_dict(),
            "optimizer": opt.state_dict(),
            "history": history,
        }
        save_payload(state_path, state)
        if on_epoch is not None:
            on_epoch(history)
        after_epoch(epoch + 1)
    made_by = {
        **made_by,
        "train_high": asdict(tc),
        "seed": seed,
        "stafpipe_version": __version__,
        "commit": commit(),
        "final": history[-1] if history else {},
    }
    model = model.cpu()  # the checkpoint, and the model returned, are for the CPU whatever trained them
    save_checkpoint(out_dir / "high_level.pt", model, made_by)
    return model, history


def after_epoch(epoch: int) -> None:
    """Called after each epoch's state is saved; tests replace it to simulate a kill."""
