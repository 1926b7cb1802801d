"""The classical and learned methods' controllers, one file each, behind one Controller interface; the registry
(stafpipe/registry.py) names them."""

from __future__ import annotations

from stafpipe.controllers.base import Controller, Event, TeamInfo
from stafpipe.registry import make_controller, method_config_class

__all__ = ["Controller", "Event", "TeamInfo", "make_controller", "method_config_class"]
