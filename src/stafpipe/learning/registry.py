"""Learned methods by name, and where each one's adapter lives: imported by name when first used, so that this
module, the training config that checks a method's name, and the methods' own packages import one way."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from stafpipe.learning.adapters import Adapter

ADAPTERS: dict[str, str] = {
    "dgnn": "stafpipe.learning.adapters:DGNNAdapter",
    "staf_planned": "stafpipe.learning.adapters:StafPlannedAdapter",
    "staf": "stafpipe.methods.staf.adapter:StafAdapter",
}
"""Learned methods by name (`train_ppo.method`, the `method` of a policy checkpoint)."""


def adapter_class(name: str) -> type[Adapter]:
    """The adapter of learned method `name` (a key of ADAPTERS)."""
    module, _, attr = ADAPTERS[name].partition(":")
    return getattr(importlib.import_module(module), attr)
