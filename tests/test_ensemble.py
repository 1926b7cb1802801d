"""`method.ensemble`: a learned method acting with the mean action of several training runs of its network. The CLI's
refusals of bad members (exit 2, nothing written) are cases of tests/data/bad_inputs.yaml."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from stafpipe.controllers import make_controller
from stafpipe.controllers.staf import StafMethodConfig
from stafpipe.errors import StafpipeError
from stafpipe.learning.checkpoint import load_policy, save_policy, shipped_policy
from stafpipe.learning.config import PolicyConfig
from stafpipe.learning.staf_net import StafPolicy
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import Worlds
from test_learned import _team


def _perturbed(path, scale: float = 0.05) -> str:
    """The shipped STAF network with every weight moved by seeded noise, saved with its training record."""
    policy, made_by = load_policy("", "staf_planned")
    gen = torch.Generator().manual_seed(7)
    with torch.no_grad():
        for p in policy.parameters():
            p.add_(scale * torch.randn(p.shape, generator=gen))
    save_policy(path, "staf_planned", policy, made_by)
    return str(path)


def _commands(cfgs: list[StafMethodConfig], steps: int) -> list[np.ndarray]:
    """Each controller's commands (steps, n, 2) on one corridor episode driven by the last controller, in each
    robot's frame (what the network's action became: clipped to [-1, 1], times max speed 1 m/s)."""
    sc = load_named_scenario("corridor")
    worlds = Worlds([sc], SensingConfig())
    obs = worlds.reset([5])
    ctrls = [make_controller(c) for c in cfgs]
    for c in ctrls:
        c.reset(_team(sc, worlds))
    out: list[list[np.ndarray]] = [[] for _ in ctrls]
    for _ in range(steps):
        cos, sin = np.cos(worlds.heading[0]), np.sin(worlds.heading[0])
        for k, c in enumerate(ctrls):
            command = c.act(obs.world(0))
            x, y = command[:, 0], command[:, 1]
            out[k].append(np.stack([cos * x + sin * y, -sin * x + cos * y], axis=-1))
        obs, _ = worlds.step(command[None])
    return [np.stack(o) for o in out]


ALONE = StafMethodConfig(
    checkpoint="shipped:staf_planned"
)  # the shipped first run by itself (no partners: not the default)


def test_an_ensemble_of_the_checkpoint_with_itself_acts_as_the_checkpoint() -> None:
    doubled = StafMethodConfig(checkpoint="shipped:staf_planned", ensemble=[str(shipped_policy("staf_planned"))])
    alone, doubled = _commands([ALONE, doubled], 40)
    assert np.abs(alone).max() > 0.1  # the team moves
    assert np.array_equal(alone, doubled)  # (x + x) / 2 is x to the bit


def test_an_ensemble_acts_with_the_mean_of_its_members_actions(tmp_path) -> None:
    other = _perturbed(tmp_path / "other.pt")
    a, b, both = _commands(
        [
            ALONE,
            StafMethodConfig(checkpoint=other),
            StafMethodConfig(checkpoint="shipped:staf_planned", ensemble=[other]),
        ],
        60,
    )
    assert np.abs(a - b).max() > 0.05  # the two networks act differently
    # where neither member's action reaches the clip, the ensemble's is their mean
    free = (np.abs(a) < 0.999) & (np.abs(b) < 0.999)
    assert free.mean() > 0.3
    np.testing.assert_allclose(both[free], ((a + b) / 2)[free], atol=1e-5)
    assert np.abs(both - a)[free].max() > 0.01  # and not the first network's alone


def test_an_ensemble_member_of_another_network_or_empty_is_refused(tmp_path) -> None:
    small = StafPolicy(PolicyConfig(hidden=32))
    save_policy(tmp_path / "small.pt", "staf_planned", small, load_policy("", "staf_planned")[1])
    with pytest.raises(StafpipeError, match=r"method\.ensemble\[0\].*another network"):
        make_controller(StafMethodConfig(ensemble=[str(tmp_path / "small.pt")]))
    with pytest.raises(StafpipeError, match=r"method\.ensemble\[1\]: empty"):
        make_controller(StafMethodConfig(ensemble=[str(shipped_policy("staf_planned")), ""]))


def test_the_shipped_second_run_is_named_shipped_and_fits_the_shipped_checkpoint() -> None:
    first, first_by = load_policy("", "staf_planned")
    second, second_by = load_policy("shipped:staf_planned_seed1", "staf_planned")
    assert second.cfg == first.cfg and (first_by["seed"], second_by["seed"]) == (0, 1)
    pairs = zip(first.state_dict().values(), second.state_dict().values(), strict=True)
    assert any(not torch.equal(a, b) for a, b in pairs)  # another run, not a copy
    make_controller(StafMethodConfig(ensemble=["shipped:staf_planned_seed1"]))  # its recorded settings are the run's
    with pytest.raises(StafpipeError, match=r"shipped:nope: no checkpoint of that name.*staf_planned_seed1") as refused:
        load_policy("shipped:nope", "staf_planned")
    assert "high_level" not in str(refused.value)  # the deep graph cut ships too, but is not a policy
    with pytest.raises(StafpipeError, match=r"not a stafpipe staf_planned policy checkpoint"):
        load_policy("shipped:dgnn", "staf_planned")


@pytest.mark.slow  # about 7 s on 2 cores
def test_the_shipped_staf_is_the_shipped_pair_and_a_users_checkpoint_acts_alone(tmp_path) -> None:
    """`method.ensemble` unset: the shipped checkpoint comes with its partner run, any other checkpoint with none."""
    pair = StafMethodConfig(checkpoint="shipped:staf_planned", ensemble=["shipped:staf_planned_seed1"])
    mine = str(tmp_path / "mine.pt")  # a user's checkpoint: here the shipped first run saved under another name
    save_policy(mine, "staf_planned", *load_policy("", "staf_planned"))
    default, explicit, alone, user = _commands([StafMethodConfig(), pair, ALONE, StafMethodConfig(checkpoint=mine)], 60)
    assert np.array_equal(default, explicit)
    assert np.array_equal(alone, user)  # the user's network by itself, not mixed with the shipped second run
    assert np.abs(default - alone).max() > 0.01
    assert np.array_equal(_commands([StafMethodConfig(ensemble=[]), ALONE], 60)[0], alone)  # [] = no partners
