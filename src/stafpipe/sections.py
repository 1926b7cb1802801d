"""A config section as its typed dataclass: the one conversion every stage uses (no stafpipe imports here, so any
module may use it without an import cycle)."""

from __future__ import annotations

from typing import Any, TypeVar

from omegaconf import OmegaConf

T = TypeVar("T")


def section(node: Any, kind: type[T]) -> T:
    """`node` (a config node of the schema, or already the object) as `kind`; checked, so a stage gets what it names."""
    obj = OmegaConf.to_object(node) if OmegaConf.is_config(node) else node
    if not isinstance(obj, kind):
        raise TypeError(f"config section is a {type(obj).__name__}, not a {kind.__name__}")
    return obj
