"""Adding a method is one package and one YAML (docs/extending.md): a toy learned method written into a temporary
package, registered from there, trained for one iteration, evaluated and exported, with no file of the repository
touched."""

from __future__ import annotations

import sys
import textwrap

import pandas as pd
import pytest

from conftest import job_dirs
from stafpipe.launch import launch
from stafpipe.pipeline import search_path_override
from stafpipe.registry import METHODS, learned_methods

TOY = '''
"""A toy learned method: each robot sees its own goal and its neighbours (DGNN's features and network) and gets a
reward for standing near the team's centre; nothing of it lives in stafpipe."""
from dataclasses import dataclass

import numpy as np

from stafpipe.config.checks import LearnedMethodChecks
from stafpipe.controllers.learned import LearnedController
from stafpipe.learning.adapters import Adapter, Step
from stafpipe.methods.dgnn.network import DGNNPolicy
from stafpipe.learning.features import features
from stafpipe.registry import Method, register


class ToyAdapter(Adapter):
    name = "toy"
    network = DGNNPolicy

    def step(self, obs, dt):
        self._aim = obs.goal
        return Step(self.features(obs), obs.goal, obs.goal)

    def features(self, obs):
        return features(obs, self.policy.goal_clip, self.sensing_radius, obs.goal)

    def reward(self, pos, vel, obs):
        return -0.01 * np.linalg.norm(pos - pos.mean(axis=1, keepdims=True), axis=-1)


@dataclass
class ToyConfig(LearnedMethodChecks):
    name: str = "toy"
    checkpoint: str = ""
    deterministic: bool = True
    sensing_radius: float = 2.0
    allow_mismatch: bool = False
    low_level: str = "learned"
    proportional_gain: float = 2.0
    approach_cap_gap: float = 0.02

    def check(self, key: str = "method") -> None:
        self.check_low_level(key)


class ToyController(LearnedController):
    pass


register("toy", Method("toyplug:ToyConfig", "toyplug:ToyController", adapter="toyplug:ToyAdapter"))
'''

TOY_YAML = """
defaults:
  - base_toy
  - _self_
name: toy
"""


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """The package `toyplug` and its conf/method/toy.yaml under tmp_path, imported (it registers itself); the
    registry is restored afterwards."""
    (tmp_path / "toyplug").mkdir()
    (tmp_path / "toyplug" / "__init__.py").write_text(textwrap.dedent(TOY))
    (tmp_path / "conf" / "method").mkdir(parents=True)
    (tmp_path / "conf" / "method" / "toy.yaml").write_text(TOY_YAML)
    monkeypatch.syspath_prepend(str(tmp_path))
    __import__("toyplug")
    yield search_path_override([tmp_path / "conf"])
    sys.modules.pop("toyplug", None)
    METHODS.pop("toy", None)


@pytest.mark.slow  # about 15 s on 2 cores: one training iteration, one episode, one export
def test_a_toy_method_in_its_own_package_trains_evaluates_and_exports(toy, workdir) -> None:
    assert "toy" in learned_methods()
    train = [
        "train_ppo.method=toy",
        "train_ppo.iterations=1",
        "train_ppo.worlds=2",
        "train_ppo.episode_steps=8",
        "train_ppo.policy.hidden=16",
    ]
    assert launch("train-ppo", train) == 0
    [run] = job_dirs(workdir)
    assert len(pd.read_parquet(run / "learning_curves.parquet")) == 1
    policy = run / "policy.pt"
    evaluate = [toy, "method=toy", f"method.checkpoint={policy}", "eval.episodes=1", "scenario.time_limit=3"]
    assert launch("eval", evaluate) == 0
    [result] = [d for d in job_dirs(workdir) if d != run]
    assert (result / "results.parquet").is_file()
    assert pd.read_parquet(result / "results.parquet").method.tolist() == ["toy"]
    pytest.importorskip("onnx")
    from stafpipe.export_onnx import export

    out = export("toy", str(policy), workdir / "toy.onnx")
    assert out.is_file() and out.stat().st_size > 0


def test_plugins_named_by_entry_points_are_loaded_once_and_a_broken_one_is_named(monkeypatch) -> None:
    import importlib.metadata

    import stafpipe.registry as registry
    from stafpipe.errors import StafpipeError

    loaded = []

    class Entry:
        def __init__(self, name: str, fails: bool) -> None:
            self.name, self.value, self.fails = name, f"{name}_pkg", fails

        def load(self) -> None:
            loaded.append(self.name)
            if self.fails:
                raise ImportError("no module named x")
            registry.register(self.name, METHODS["straight"], replace=True)  # monkeypatch set it: undone after

    entries = [Entry("plugged", False)]
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: entries if group == registry.PLUGINS else [])
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    monkeypatch.setitem(METHODS, "plugged", METHODS["straight"])  # removed again by monkeypatch
    registry.load_plugins()
    registry.load_plugins()
    assert loaded == ["plugged"]
    entries[:] = [Entry("broken", True)]
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    with pytest.raises(StafpipeError, match=r"method plugin broken \(broken_pkg\) failed to load"):
        registry.method_config_class("straight")


def test_register_refuses_a_reserved_or_taken_name_unless_told_to_replace(monkeypatch) -> None:
    from stafpipe.errors import StafpipeError
    from stafpipe.registry import register

    with pytest.raises(StafpipeError, match="other than"):
        register("high", METHODS["straight"])
    with pytest.raises(StafpipeError, match="exists"):
        register("straight", METHODS["lf"])
    monkeypatch.setitem(METHODS, "straight", METHODS["straight"])  # restored afterwards
    register("straight", METHODS["lf"], replace=True)
    assert METHODS["straight"] is METHODS["lf"]
