"""Decentralised distributed PPO (DD-PPO; Wijmans et al., "DD-PPO: Learning near-perfect PointGoal navigators from
2.5 billion frames", ICLR 2020): `train_ppo.workers=N` processes, each stepping its share of the worlds and computing
PPO's gradients on its own samples, the gradients averaged over the workers at every minibatch so that every worker
takes the same optimiser step and keeps the same weights. No parameter server and no rollout-only workers: the update
is most of an iteration's time on a CPU (docs/learning.md), so it is split too.

The engine is torch.distributed: the processes are started by its elastic launcher (the API behind `torchrun
--standalone`) and talk over gloo, which runs on any CPU (docs/decisions.md, "Distributed PPO"). `Workers()` (one
process) makes every collective a no-op, so a single-process run does exactly what it did without this module.
"""

from __future__ import annotations

import datetime
import hashlib
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import torch
import torch.distributed as dist

from stafpipe.errors import StafpipeError

RANK_SEED_STRIDE = 1_000_003
"""A worker's torch seeds (action noise, minibatch order) are `seed + rank x this`; rank 0 keeps the run's seed, so
one worker draws exactly what a run without workers draws."""
WAIT = datetime.timedelta(hours=24)
"""How long a collective waits for the other workers: rank 0 alone runs the warm start (the imitation rounds of
`train_ppo.imitation`, up to an hour) while the others wait for its weights; gloo's default of 30 minutes is too
short for that."""


@dataclass(frozen=True)
class Workers:
    """This process's place among the training workers: `rank` of `size`. With size 1 nothing is communicated."""

    rank: int = 0
    size: int = 1

    @property
    def main(self) -> bool:
        """The worker that writes files and runs what is not split (the warm start)."""
        return self.rank == 0

    def seed(self, seed: int) -> int:
        return seed + RANK_SEED_STRIDE * self.rank

    def share(self, count: int) -> range:
        """This worker's indices of `count` items split evenly in order (count a multiple of size)."""
        per = count // self.size
        return range(self.rank * per, (self.rank + 1) * per)

    def average_gradients(self, params: Iterable[torch.nn.Parameter]) -> None:
        """Every parameter's gradient replaced by its mean over the workers (one all-reduce of a flat buffer, on the
        CPU: gloo's), a missing gradient counted as zeros; a parameter no worker has a gradient for keeps none, as
        in one process (the optimiser then leaves it alone)."""
        if self.size == 1:
            return
        params = list(params)
        grads = [p.grad if p.grad is not None else torch.zeros_like(p) for p in params]
        has = torch.tensor([float(p.grad is not None) for p in params])
        flat = torch.cat([*(g.detach().reshape(-1).cpu() for g in grads), has])
        dist.all_reduce(flat)
        flat /= self.size
        start = 0
        for p, g, anyone in zip(params, grads, flat[-len(params) :].tolist(), strict=True):
            part = flat[start : start + g.numel()].view_as(g).to(g.device)
            start += g.numel()
            if anyone == 0:
                p.grad = None
            elif p.grad is None:
                p.grad = part
            else:
                p.grad.copy_(part)

    def total(self, values: list[float], op: str = "sum") -> list[float]:
        """`values` summed (or their `max`) over the workers, in float64; the same list on every worker."""
        if self.size == 1:
            return list(values)
        t = torch.tensor(values, dtype=torch.float64)
        dist.all_reduce(t, op=dist.ReduceOp.MAX if op == "max" else dist.ReduceOp.SUM)
        return t.tolist()

    def mean(self, stats: dict[str, float]) -> dict[str, float]:
        """Per-worker means over equal shares, averaged over the workers (keys in the same order everywhere)."""
        if self.size == 1:
            return stats
        keys = list(stats)
        every = self.gather(keys)
        names = every[0]  # the main worker's order, the same list everywhere
        if any(sorted(k) != sorted(names) for k in every):
            raise RuntimeError(f"train_ppo.workers: the workers' statistics differ in their names ({keys})")
        return dict(zip(names, (v / self.size for v in self.total([stats[k] for k in names])), strict=True))

    def from_main(self, module: torch.nn.Module, extra: Any = None) -> Any:
        """`module`'s weights and the picklable `extra` made equal to the main worker's; returns its `extra`."""
        if self.size == 1:
            return extra
        for tensor in module.state_dict().values():
            dist.broadcast(tensor, src=0)
        box = [extra]
        dist.broadcast_object_list(box, src=0)
        return box[0]

    def gather(self, obj: Any) -> list[Any]:
        """Every worker's `obj`, in rank order, on every worker."""
        if self.size == 1:
            return [obj]
        out: list[Any] = [None] * self.size
        dist.all_gather_object(out, obj)
        return out

    def check_in_step(self, module: torch.nn.Module) -> None:
        """Raises if the workers' weights differ: averaged gradients and the same optimiser keep them equal to the
        bit, so a difference is a bug, never noise."""
        if self.size == 1:
            return
        digest = hashlib.sha256(b"".join(t.detach().cpu().numpy().tobytes() for t in module.state_dict().values()))
        seen = self.gather(digest.hexdigest())
        if len(set(seen)) != 1:
            raise RuntimeError(f"train_ppo.workers: the workers' weights differ after training ({seen})")


def joined() -> Workers:
    """Join the process group of a worker started by `launch` (torch.distributed's environment variables)."""
    dist.init_process_group("gloo", timeout=WAIT)
    return Workers(dist.get_rank(), dist.get_world_size())


def leave() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def launch(count: int, entry: Callable[..., Any], *args: Any) -> Any:
    """Run `entry(*args)` in `count` local worker processes through torch.distributed's elastic launcher (what
    `torchrun --standalone --nproc-per-node=count` does) and return rank 0's result. A worker's StafpipeError comes
    back as one (with `entry` decorated by torch's `record`, which passes its message), any other failure as a
    RuntimeError naming the worker, Ctrl-C as KeyboardInterrupt."""
    from torch.distributed.elastic.multiprocessing.api import SignalException
    from torch.distributed.elastic.multiprocessing.errors import ChildFailedError
    from torch.distributed.launcher.api import LaunchConfig, elastic_launch

    config = LaunchConfig(
        min_nodes=1,
        max_nodes=1,
        nproc_per_node=count,
        run_id=f"stafpipe-train-ppo-{os.getpid()}",
        rdzv_backend="c10d",
        rdzv_endpoint="127.0.0.1:0",  # a free port, as torchrun --standalone picks
        max_restarts=0,  # a failed worker fails the run: a restart would train from a state the others left
        start_method="spawn",
    )
    try:
        return elastic_launch(config, entry)(*args)[0]
    except SignalException:
        raise KeyboardInterrupt from None
    except ChildFailedError as failed:
        rank, failure = failed.get_first_failure()
        said = failure.message.get("message", "") if isinstance(failure.message, dict) else str(failure.message)
        kind, _, text = said.partition(": ")
        if kind in _names(StafpipeError):
            raise StafpipeError(text) from None
        raise RuntimeError(
            f"train_ppo.workers: worker {rank} failed ({said or f'exit code {failure.exitcode}'})"
        ) from None


def _names(kind: type) -> set[str]:
    """The names of `kind` and of its subclasses."""
    subclasses: list[type] = kind.__subclasses__()
    return {kind.__name__}.union(*(_names(sub) for sub in subclasses))


ALONE = Workers()
"""One process: no collectives."""
