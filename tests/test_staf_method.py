"""`method=staf`, the paper's STAF: registered, driven through its adapter, its ablation switches and its refusals."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from conftest import job_dirs
from stafpipe.controllers import make_controller
from stafpipe.controllers.base import TeamInfo
from stafpipe.episode import episode_context
from stafpipe.geometry import Geometry
from stafpipe.launch import launch
from stafpipe.learning.checkpoint import build_policy, save_policy
from stafpipe.learning.config import PolicyConfig
from stafpipe.methods.staf.method import StafConfig
from stafpipe.methods.staf.subteaming import SubteamingConfig
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import Worlds


def _checkpoint(tmp_path, subteaming: dict | None = None) -> str:
    """A small untrained STAF network saved as a policy checkpoint, its training record naming every `subteaming`
    setting (the defaults, with `subteaming`'s values)."""
    import dataclasses

    torch.manual_seed(0)
    policy = build_policy("staf", PolicyConfig(hidden=16))
    recorded = {**dataclasses.asdict(SubteamingConfig()), **(subteaming or {})}
    made_by = {"train_ppo": {"subteaming": recorded}, "sensing": {"radius": 2.0}}
    return str(save_policy(tmp_path / "policy.pt", "staf", policy, made_by))


def _team(sc, worlds: Worlds) -> TeamInfo:
    ctx, path = episode_context(sc, Geometry(sc), SensingConfig(), 0.3, 0.1)
    return TeamInfo(sc, worlds.pos[0].copy(), worlds.goal[0].copy(), sc.template(), path, ctx.passage_width)


def test_staf_divides_the_corridor_wedge_into_two_subteams_of_five_and_zeroed_messages_change_the_action(
    tmp_path,
) -> None:
    sc = load_named_scenario("corridor")
    worlds = Worlds([sc], SensingConfig())
    obs = worlds.reset([0])
    ctrl = make_controller(StafConfig(checkpoint=_checkpoint(tmp_path)))
    ctrl.reset(_team(sc, worlds))
    first = ctrl.act(obs.world(0))
    assert sorted(np.bincount(ctrl.subteams)) == [5, 5]  # Sec. 7: two balanced subteams of the 2.4 m corridor's wedge
    silent = make_controller(StafConfig(checkpoint=ctrl.cfg.checkpoint, messages=False))
    silent.reset(_team(sc, worlds))
    assert not np.allclose(silent.act(obs.world(0)), first)  # the messages reach the action, and the switch cuts them
    assert not silent.adapter.features(obs).mask.any()


@pytest.mark.slow
def test_a_staf_checkpoint_trained_under_other_subteaming_rules_is_refused(workdir, tmp_path) -> None:
    path = _checkpoint(tmp_path, {"m": 3, "min_spacing": 0.6})
    words = [f"method.checkpoint={path}", "eval.episodes=1", "scenario.time_limit=1"]
    assert launch("eval", ["method=staf", *words]) == 2  # trained with m=3, run with m chosen by the width
    assert not job_dirs(workdir)
    assert launch("eval", ["method=staf", "method.subteaming.m=3", *words]) == 0
    assert launch("eval", ["method=staf", "method.subteaming.min_spacing=0", *words]) == 2  # a bad value, named


@pytest.mark.slow
def test_the_warm_start_teacher_alone_passes_the_corridor_in_two_subteams(workdir, tmp_path) -> None:
    """`method.low_level=orca`: the imitation teacher drives (ablation iii); a known outcome on the corridor."""
    words = [f"method.checkpoint={_checkpoint(tmp_path)}", "method.low_level=orca", "formation=wedge"]
    assert launch("eval", ["method=staf", "scenario=corridor", "eval.episodes=1", *words]) == 0
    (run,) = job_dirs(workdir)
    row = pd.read_csv(run / "results.csv").iloc[0]
    assert row.sr == 1.0 and row.collisions == 0 and row.subteams_max == 2


def test_subteaming_settings_are_checked_by_name() -> None:
    with pytest.raises(Exception, match=r"method.subteaming.lookahead"):
        StafConfig(subteaming=SubteamingConfig(lookahead=0)).check()
