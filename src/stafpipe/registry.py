"""Every method by name, one record each: where its config and controller live and, for a learned method, its adapter
(features, targets, reward terms; the adapter names its network) and the shipped training runs its shipped policy
acts with. Evaluation (`method=NAME`), training (`train_ppo.method=NAME`), export (`stafpipe export NAME`), the
PettingZoo environment and `stafpipe compare` all look a method up here and nowhere else.

Classes are named as "module:Class" strings and imported when first used, so that this module imports nothing of the
methods' and any module may import it (docs/extending.md: adding a method is one package, one entry here or one call
to `register`, and one YAML under conf/method/)."""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from stafpipe.errors import StafpipeError

if TYPE_CHECKING:
    from stafpipe.controllers.base import Controller
    from stafpipe.learning.adapters import Adapter


@dataclass(frozen=True)
class Method:
    """One method's record."""

    config: str
    """"module:Class" of its config dataclass (the `method` group's node for `method=NAME`)."""
    controller: str
    """"module:Class" of its controller, built from that config."""
    adapter: str = ""
    """Learned methods: "module:Class" of the adapter that training and evaluation both drive it through; its
    `network` is the policy network (trained by `train-ppo`, exported by `stafpipe export`)."""
    partners: tuple[str, ...] = ()
    """Learned methods: more shipped runs (`shipped:NAME`) the shipped policy acts with, averaged, when
    `method.ensemble` is unset (learning/checkpoint.py:ensemble_paths)."""


METHODS: dict[str, Method] = {
    "straight": Method(
        "stafpipe.methods.straight.method:StraightConfig", "stafpipe.methods.straight.method:StraightController"
    ),
    "lf": Method("stafpipe.controllers.lf:LFConfig", "stafpipe.controllers.lf:LFController"),
    "cezayirli": Method(
        "stafpipe.methods.cezayirli.method:CezayirliConfig", "stafpipe.methods.cezayirli.method:CezayirliController"
    ),
    "zhu": Method("stafpipe.controllers.zhu_config:ZhuConfig", "stafpipe.controllers.zhu:ZhuController"),
    "dgnn": Method(
        "stafpipe.methods.dgnn.method:DGNNConfig",
        "stafpipe.methods.dgnn.method:DGNNController",
        adapter="stafpipe.methods.dgnn.adapter:DGNNAdapter",
    ),
    "staf_planned": Method(
        "stafpipe.controllers.staf:StafMethodConfig",
        "stafpipe.controllers.staf:StafController",
        adapter="stafpipe.learning.adapters:StafPlannedAdapter",
        partners=("shipped:staf_planned_seed1",),  # two runs averaged: the STAF-planned journal, "The pair"
    ),
    "staf": Method(
        "stafpipe.methods.staf.method:StafConfig",
        "stafpipe.methods.staf.method:StafController",
        adapter="stafpipe.methods.staf.adapter:StafAdapter",
    ),
    "onnx": Method("stafpipe.controllers.onnx_policy:OnnxConfig", "stafpipe.controllers.onnx_policy:OnnxController"),
}
"""Methods by `method.name`."""


PLUGINS = "stafpipe.methods"
"""The entry-point group a package outside stafpipe names its methods' modules in (docs/extending.md); each is imported
once, before the first lookup, and registers its methods with `register`."""
_plugins_loaded = False


RESERVED = ("high",)
"""Names no method may take: `stafpipe export high` is the deep graph cut."""


def register(name: str, method: Method, replace: bool = False) -> None:
    """Add a method from outside the package (a user's own). `method=NAME` then needs `method/NAME.yaml` on the config
    search path (`--config-dir`), whose defaults start from `base_NAME`, the config class's node. A name already taken
    is refused unless `replace`."""
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name) or name in RESERVED:
        raise StafpipeError(f"register: a method's name is an ASCII identifier other than {RESERVED}, got {name!r}")
    if name in METHODS and not replace:
        raise StafpipeError(f"register: method {name!r} exists; pass replace=True to replace it")
    METHODS[name] = method


def load_plugins() -> dict[str, Method]:
    """Import every module named in the `stafpipe.methods` entry-point group (once) and return the registry."""
    global _plugins_loaded
    if not _plugins_loaded:
        from importlib.metadata import entry_points

        for entry in entry_points(group=PLUGINS):
            try:
                entry.load()
            except Exception as exc:  # a broken plugin names itself, not a traceback; it fails again next time
                raise StafpipeError(f"method plugin {entry.name} ({entry.value}) failed to load: {exc}") from exc
        _plugins_loaded = True
    return METHODS


def _load(ref: str) -> Any:
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


def record(name: str) -> Method:
    if name not in load_plugins():
        raise StafpipeError(f"method must be one of {sorted(METHODS)}, got {name!r}")
    return METHODS[name]


def learned_methods() -> list[str]:
    """Names of the methods with a learned policy (`train_ppo.method`, `stafpipe export`), sorted."""
    return sorted(name for name, m in load_plugins().items() if m.adapter)


def method_config_class(name: str) -> type:
    """The config dataclass of method `name`."""
    return _load(record(name).config)


def make_controller(cfg: Any) -> Controller:
    """The controller of a method config (a dataclass instance with a `name`)."""
    return _load(record(cfg.name).controller)(cfg)


def adapter_class(name: str) -> type[Adapter]:
    """The adapter of learned method `name`."""
    adapter = record(name).adapter
    if not adapter:
        raise StafpipeError(f"{name!r} is not a learned method; learned methods: {learned_methods()}")
    return _load(adapter)
