"""Checks every run's config gets before any work (`launch.stage_task`), whatever its stage: keys the schema does
not know (a misspelled `+eval.episode=3` would otherwise be dropped silently), NaN or infinity anywhere, a negative
seed, and the sections every stage shares (world, sensing, eval). Stage-specific ranges are checked by each
section's own `check()` where its stage reads it."""

from __future__ import annotations

import dataclasses
import difflib
import math
from collections.abc import Sequence
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf

from stafpipe.errors import ConfigError, require

SEED_STRIDE = 100_003
"""Episode k of a run seeded s is seeded s x SEED_STRIDE + k (`stages.eval.episode_seed`): a prime stride, so runs
with nearby seeds share no episode seed for the first 100,003 episodes."""
MAX_SEED = (2**63 - 1) // SEED_STRIDE - SEED_STRIDE
"""The largest run seed whose episode seeds fit the 64-bit integers of the episode logs (about 9.2e13)."""


def check_run_config(cfg: DictConfig, overrides: Sequence[str] = ()) -> None:
    """Every run's config before any work; `overrides`: the command line's, for the rules that depend on what was
    given rather than on the composed values."""
    _unknown_keys(cfg, "")
    _scenario_fields_beside_path(cfg, overrides)
    _non_finite(OmegaConf.to_container(cfg, resolve=True), "")
    require(
        0 <= int(cfg.seed) <= MAX_SEED, "seed", f"must be in [0, {MAX_SEED}] (episode seeds must fit 64 bits)", cfg.seed
    )
    for key in ("world", "sensing", "eval", *STAGE_SECTIONS.get(str(cfg.get("stage")), ())):
        if key in cfg and cfg[key] is not None:
            check = getattr(OmegaConf.to_object(cfg[key]), "check", None)
            if check is not None:
                check(key)
    _method_with_the_run(cfg)


STAGE_SECTIONS: dict[str, tuple[str, ...]] = {
    "generate": ("data", "formation"),
    "generate-maps": ("maps",),
    "train-high": ("high", "train_high"),
    "train-ppo": ("train_ppo",),
    "ablate": ("ablate", "high", "train_high"),
    "eval": ("method",),
    "plot": ("plot",),
}
"""The sections each stage reads, besides world, sensing and eval: checked with the rest before any work (and for
every job of a sweep before its first job runs)."""


def _scenario_fields_beside_path(cfg: DictConfig, overrides: Sequence[str]) -> None:
    """`scenario.path` replaces the scenario group's fields with the file's, so a `scenario.<field>=` override beside
    it would be dropped without a word (a time limit, say, with the file's own in force), and so would a choice of
    built-in scenario (`scenario=bridge`): both refused, naming the key."""
    if "scenario" not in cfg or cfg.scenario is None or not cfg.scenario.get("path"):
        return
    for override in overrides:
        key = override.split("=", 1)[0].lstrip("+~").strip()
        if key == "scenario" or (key.startswith("scenario.") and key != "scenario.path"):
            raise ConfigError(
                f"{key}: not applied beside scenario.path (the scenario file replaces the scenario's fields); "
                f"set it in {cfg.scenario.path}, or leave scenario.path out"
            )


def _method_with_the_run(cfg: DictConfig) -> None:
    """Cross-section rules: a method whose settings must agree with the run's sensing and world (its
    `check_run(sensing, world, key)`: a learned method's radius, Cezayirli's d_max, range error and period)."""
    if "method" not in cfg or "sensing" not in cfg or "world" not in cfg or cfg.method is None:
        return
    method = OmegaConf.to_object(cfg.method)
    check_run = getattr(method, "check_run", None)
    if check_run is not None:
        check_run(OmegaConf.to_object(cfg.sensing), OmegaConf.to_object(cfg.world), "method")


def _unknown_keys(node: DictConfig, path: str) -> None:
    kind = OmegaConf.get_type(node)
    if kind is not None and dataclasses.is_dataclass(kind):
        known = [f.name for f in dataclasses.fields(kind)]
        for key in map(str, node):
            if key not in known:
                name = f"{path}.{key}" if path else str(key)
                close = difflib.get_close_matches(str(key), known, n=1)
                hint = f" (did you mean {path + '.' if path else ''}{close[0]}?)" if close else ""
                raise ConfigError(f"{name} is not a setting of `{path or 'the config'}`{hint}")
    for key in map(str, node):
        child = node._get_node(key)  # the node itself, so that its type is kept
        if isinstance(child, DictConfig):
            _unknown_keys(child, f"{path}.{key}" if path else str(key))
        elif isinstance(child, ListConfig) and not child._is_none():  # an unset optional list has no items
            for i, item in enumerate(child._iter_ex(resolve=False)):
                if isinstance(item, DictConfig):
                    _unknown_keys(item, f"{path}.{key}[{i}]" if path else f"{key}[{i}]")


def _non_finite(node: Any, path: str) -> None:  # node: a plain container (dicts, lists, values)
    if isinstance(node, dict):
        for key, value in node.items():
            _non_finite(value, f"{path}.{key}" if path else str(key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            _non_finite(value, f"{path}[{i}]")
    elif isinstance(node, float) and not math.isfinite(node):
        raise ConfigError(f"{path} must be a finite number, got {node}")


def check_sensing_radius(mine: float, run: float, allowed: bool, key: str) -> None:
    """A learned method's `sensing_radius` is > 0 and equals the run's `sensing.radius` (its features clip what the
    robot senses at its own radius, so a larger world radius would show it neighbours it never saw in training),
    unless `allow_mismatch`."""
    require(mine > 0, f"{key}.sensing_radius", "must be > 0", mine)
    if not allowed and not math.isclose(mine, run):
        raise ConfigError(
            f"{key}.sensing_radius ({mine:g}) differs from sensing.radius ({run:g}): set both to the radius the "
            f"policy was trained with (its checkpoint's made_by), or {key}.allow_mismatch=true"
        )


class LearnedMethodChecks:
    """The checks every learned method's config shares (`method=dgnn`, `staf`, `staf_planned`): its hand-made low level
    and safety-layer gap, and, with the run's sensing, the radius its policy was trained with."""

    sensing_radius: float
    allow_mismatch: bool
    low_level: str
    proportional_gain: float
    approach_cap_gap: float

    def check_low_level(self, key: str, stop_gap: float | None = None) -> None:
        from stafpipe.learning.teachers import check_low_level, check_stop_gap

        if stop_gap is None:
            check_low_level(self.low_level, self.proportional_gain, key)
        else:
            check_low_level(self.low_level, self.proportional_gain, key, stop_gap)
        check_stop_gap(self.approach_cap_gap, f"{key}.approach_cap_gap")

    def check_run(self, sensing: Any, world: Any, key: str = "method") -> None:
        """With the run's sensing: the policy's features clip what it senses at its own radius."""
        check_sensing_radius(self.sensing_radius, sensing.radius, self.allow_mismatch, key)
