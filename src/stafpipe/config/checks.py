"""Checks every run's config gets before any work (`launch.stage_task`), whatever its stage: keys the schema does
not know (a misspelled `+eval.episode=3` would otherwise be dropped silently), NaN or infinity anywhere, a negative
seed, and the sections every stage shares (world, sensing, eval). Stage-specific ranges are checked by each
section's own `check()` where its stage reads it."""

from __future__ import annotations

import dataclasses
import difflib
import math
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf

from stafpipe.errors import ConfigError, require


def check_run_config(cfg: DictConfig) -> None:
    _unknown_keys(cfg, "")
    _non_finite(OmegaConf.to_container(cfg, resolve=True), "")
    require(int(cfg.seed) >= 0, "seed", "must be >= 0", cfg.seed)
    for key in ("world", "sensing", "eval"):
        if key in cfg:
            section = OmegaConf.to_object(cfg[key])
            section.check(key)  # type: ignore[union-attr]


def _unknown_keys(node: DictConfig, path: str) -> None:
    kind = OmegaConf.get_type(node)
    if kind is not None and dataclasses.is_dataclass(kind):
        known = [f.name for f in dataclasses.fields(kind)]
        for key in node.keys():
            if key not in known:
                name = f"{path}.{key}" if path else str(key)
                close = difflib.get_close_matches(str(key), known, n=1)
                hint = f" (did you mean {path + '.' if path else ''}{close[0]}?)" if close else ""
                raise ConfigError(f"{name} is not a setting of `{path or 'the config'}`{hint}")
    for key in node.keys():
        child = node._get_node(key)  # noqa: SLF001 - the node itself, so that its type is kept
        if isinstance(child, DictConfig):
            _unknown_keys(child, f"{path}.{key}" if path else str(key))
        elif isinstance(child, ListConfig):
            for i, item in enumerate(child._iter_ex(resolve=False)):  # noqa: SLF001
                if isinstance(item, DictConfig):
                    _unknown_keys(item, f"{path}.{key}[{i}]" if path else f"{key}[{i}]")


def _non_finite(node: Any, path: str) -> None:  # noqa: ANN401 - a plain container
    if isinstance(node, dict):
        for key, value in node.items():
            _non_finite(value, f"{path}.{key}" if path else str(key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            _non_finite(value, f"{path}[{i}]")
    elif isinstance(node, float) and not math.isfinite(node):
        raise ConfigError(f"{path} must be a finite number, got {node}")
