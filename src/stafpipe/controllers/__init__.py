"""Methods, one file each, behind one Controller interface; `METHODS` maps a `method.name` to its config and class."""

from __future__ import annotations

import importlib
from typing import Any

from stafpipe.controllers.base import Controller, Event, TeamInfo

# name -> ("module:ConfigClass", "module:ControllerClass")
METHODS: dict[str, tuple[str, str]] = {
    "straight": ("stafpipe.controllers.straight:StraightConfig", "stafpipe.controllers.straight:StraightController"),
    "lf": ("stafpipe.controllers.lf:LFConfig", "stafpipe.controllers.lf:LFController"),
    "cezayirli": (
        "stafpipe.controllers.cezayirli:CezayirliConfig",
        "stafpipe.controllers.cezayirli:CezayirliController",
    ),
    "zhu": ("stafpipe.controllers.zhu_config:ZhuConfig", "stafpipe.controllers.zhu:ZhuController"),
    "dgnn": ("stafpipe.controllers.dgnn:DGNNConfig", "stafpipe.controllers.dgnn:DGNNController"),
    "staf_planned": ("stafpipe.controllers.staf:StafMethodConfig", "stafpipe.controllers.staf:StafController"),
    "staf": ("stafpipe.methods.staf.method:StafConfig", "stafpipe.methods.staf.method:StafController"),
    "onnx": ("stafpipe.controllers.onnx_policy:OnnxConfig", "stafpipe.controllers.onnx_policy:OnnxController"),
}

__all__ = ["METHODS", "Controller", "Event", "TeamInfo", "make_controller", "method_config_class"]


def _load(ref: str) -> Any:
    module, _, name = ref.partition(":")
    return getattr(importlib.import_module(module), name)


def method_config_class(name: str) -> type:
    """The config dataclass of method `name`."""
    return _load(METHODS[name][0])


def make_controller(cfg: Any) -> Controller:
    """Build the controller of a method config (a dataclass instance with a `name`)."""
    return _load(METHODS[cfg.name][1])(cfg)
