"""The PPO trainer: GAE known answer, determinism, exact resume, the train-ppo stage and the dgnn method."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import torch
from typer.testing import CliRunner

import stafpipe.learning.ppo as ppo
from conftest import job_dirs, tensorboard_scalars
from stafpipe.cli import app
from stafpipe.errors import StafpipeError
from stafpipe.launch import launch
from stafpipe.learning.checkpoint import load_policy
from stafpipe.learning.config import ImitationConfig, PolicyConfig, TrainPPOConfig
from stafpipe.learning.rollout import gae
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig

TINY = [
    "train_ppo.iterations=2",
    "train_ppo.worlds=2",
    "train_ppo.episode_steps=8",
    "train_ppo.policy.hidden=16",
    "train_ppo.checkpoint_every=1",
]


def test_gae_matches_a_hand_computed_case() -> None:
    r, v = torch.tensor([1.0, 0.0, 2.0]), torch.tensor([0.5, 0.2, 0.1])
    g, lam, last = 0.9, 0.8, torch.tensor(0.3)
    d2 = 2.0 + g * 0.3 - 0.1
    d1 = 0.0 + g * 0.1 - 0.2
    d0 = 1.0 + g * 0.2 - 0.5
    a2 = d2
    a1 = d1 + g * lam * a2
    a0 = d0 + g * lam * a1
    adv, ret = gae(r, v, last, g, lam)
    assert torch.allclose(adv, torch.tensor([a0, a1, a2])) and torch.allclose(ret, adv + v)


def test_guide_targets_follow_the_path_then_release_to_the_goal() -> None:
    from stafpipe.learning.features import guide_targets

    path = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    pos = np.array([[2.0, 1.0], [9.0, -1.0], [10.5, 7.0]])
    goal = np.array([[12.0, 12.0], [8.0, 12.0], [11.0, 10.0]])
    got = guide_targets(pos, goal, path, lookahead=2.0, release=4.0)[0]
    # robot 0 projects to arc 2 -> 4 ahead: (4, 0); robot 1 to arc 9 -> 11: (10, 1); robot 2 to arc 17, 3 from the end
    assert np.allclose(got, [[4.0, 0.0], [10.0, 1.0], [11.0, 10.0]])


def _train(out_dir, iterations=3, resume_from=None, on_iteration=lambda h: None, **extra):
    tc = TrainPPOConfig(
        iterations=iterations,
        worlds=2,
        episode_steps=6,
        policy=PolicyConfig(hidden=16),
        **{"checkpoint_every": 1, "minibatches": 2, "epochs": 2, **extra},
    )
    corridor = load_named_scenario("corridor")
    path = np.array([[4.0, 6.0], [26.0, 6.0]])
    out_dir.mkdir(parents=True, exist_ok=True)
    return ppo.train_ppo(
        tc,
        lambda rng, k: [(corridor, path, 2.4)] * k,
        WorldConfig(),
        SensingConfig(),
        0.3,
        4,
        out_dir,
        "h",
        resume_from,
        on_iteration,
    )


def _same(a, b) -> bool:
    return all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values(), strict=True))


@pytest.mark.parametrize("method", [pytest.param("dgnn", marks=pytest.mark.slow), "staf"])  # dgnn: about 6 s
def test_training_is_deterministic_and_resumes_exactly(tmp_path, method) -> None:
    full, hist = _train(tmp_path / "a", method=method)
    again, _ = _train(tmp_path / "b", method=method)
    assert _same(full, again)
    assert all(math.isfinite(v) for row in hist for v in row.values() if isinstance(v, float))

    def killed(history) -> None:
        if len(history) == 2:
            raise KeyboardInterrupt  # after iteration 2's state was saved

    with pytest.raises(KeyboardInterrupt):
        _train(tmp_path / "c", on_iteration=killed, method=method)
    resumed, rhist = _train(tmp_path / "c", resume_from=tmp_path / "c" / ppo.STATE_FILE, method=method)
    assert _same(full, resumed)
    assert [r["iteration"] for r in rhist] == [1, 2, 3]
    assert [r["charts/episode_return"] for r in rhist] == [r["charts/episode_return"] for r in hist]


def test_a_kill_after_the_warm_start_resumes_without_redoing_it(tmp_path) -> None:
    warm = {"imitation": ImitationConfig(epochs=1, rollouts=1, dagger=1, teacher="avoiding"), "checkpoint_every": 5}
    full, hist = _train(tmp_path / "a", iterations=2, **warm)

    def killed(history) -> None:
        raise KeyboardInterrupt  # in iteration 1, before its state is saved: only the warm start's is on disk

    with pytest.raises(KeyboardInterrupt):
        _train(tmp_path / "b", iterations=2, on_iteration=killed, **warm)
    assert torch.load(tmp_path / "b" / ppo.STATE_FILE, weights_only=True)["iteration"] == 0
    resumed, rhist = _train(tmp_path / "b", iterations=2, resume_from=tmp_path / "b" / ppo.STATE_FILE, **warm)
    assert _same(full, resumed)
    assert rhist[0]["imitation/loss"] == hist[0]["imitation/loss"] > 0


@pytest.mark.slow  # over 10 s on 2 cores
def test_train_ppo_stage_resume_eval_and_plot(workdir) -> None:
    assert launch("train-ppo", TINY) == 0
    [run] = job_dirs(workdir)
    curves = pd.read_parquet(run / "learning_curves.parquet")
    assert list(curves.iteration) == [1, 2] and curves["losses/value"].notna().all()
    policy, made_by = load_policy(run / "policy.pt", "dgnn")
    assert made_by["iterations"] == 2 and policy.cfg.hidden == 16
    board = tensorboard_scalars(run)
    wanted = {
        "charts/success_rate",
        "charts/episode_return",
        "charts/collisions_per_episode",
        "losses/policy",
        "losses/value",
        "losses/approx_kl",
        "losses/clipfrac",
        "charts/fps",
    }
    assert wanted <= set(board), wanted - set(board)
    assert [step for step, _ in board["charts/success_rate"]] == [1, 2]
    # resume=true finds the finished state of the same config and has nothing left to do
    assert launch("train-ppo", [*TINY, "train_ppo.resume=true"]) == 0
    second = next(d for d in job_dirs(workdir) if d != run)
    assert len(pd.read_parquet(second / "learning_curves.parquet")) == 2
    assert (
        launch(
            "eval", ["method=dgnn", f"method.checkpoint={run}/policy.pt", "eval.episodes=1", "scenario.time_limit=3"]
        )
        == 0
    )
    result = CliRunner().invoke(app, ["plot", "training", str(run)])
    assert result.exit_code == 0 and "learning_curves.png" in result.output


@pytest.mark.slow  # about 2 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_bad_policy_checkpoint_and_settings_are_refused(workdir) -> None:
    (workdir / "junk.pt").write_bytes(b"junk")
    assert launch("eval", ["method=dgnn", "method.checkpoint=junk.pt", "eval.episodes=1"]) == 2
    assert launch("train-ppo", [*TINY, "train_ppo.clip=1.5"]) == 2
    assert launch("train-ppo", [*TINY, "train_ppo.team_sizes=[1]"]) == 2
    assert launch("train-ppo", [*TINY, "train_ppo.method=staf_planned", "train_ppo.plan.m=7"]) == 2
    assert launch("eval", ["method=staf_planned", "method.checkpoint=junk.pt", "eval.episodes=1"]) == 2
    assert launch("eval", ["method=staf_planned", "method.plan.speed=0", "eval.episodes=1"]) == 2
    assert not job_dirs(workdir)


def test_init_from_starts_at_the_loaded_weights_and_refuses_other_settings(tmp_path) -> None:
    from stafpipe.errors import StafpipeError
    from stafpipe.learning.checkpoint import save_policy

    trained, _ = _train(tmp_path / "a", iterations=1)
    saved = save_policy(tmp_path / "policy.pt", "dgnn", trained, {})
    # no PPO step can change the weights at lr ~0: the run ends where it started, at the loaded network
    tuned, _ = _train(tmp_path / "b", iterations=1, init_from=str(saved), lr=1e-30)
    assert _same(trained, tuned)
    fresh, _ = _train(tmp_path / "c", iterations=1, lr=1e-30)
    assert not _same(trained, fresh)
    with pytest.raises(StafpipeError, match=r"train_ppo.init_from.*hidden"):
        ppo.train_ppo(
            TrainPPOConfig(init_from=str(saved), policy=PolicyConfig(hidden=8)),
            lambda rng, k: [],
            WorldConfig(),
            SensingConfig(),
            0.3,
            4,
            tmp_path / "d",
            "h",
            None,
            lambda h: None,
        )


def test_near_weight_reweights_the_samples_where_the_teacher_brakes(tmp_path) -> None:
    from stafpipe.learning.config import RewardConfig
    from stafpipe.learning.ppo import _teacher_samples
    from stafpipe.registry import adapter_class

    tc = TrainPPOConfig(
        worlds=1,
        episode_steps=40,
        policy=PolicyConfig(hidden=16),
        imitation=ImitationConfig(epochs=1, teacher="avoiding", near_weight=5.0, noise=0.0),
    )
    corridor = load_named_scenario("corridor")
    adapter = adapter_class("dgnn")(tc.policy, RewardConfig(), None, 2.0)
    drawn = [(corridor, np.array([[4.0, 6.0], [26.0, 6.0]]), 2.4)]
    *_, weight = _teacher_samples(None, adapter, drawn, WorldConfig(), SensingConfig(), tc, np.random.default_rng(0))
    # a circle of 10 at 1 m spacing: some robots brake for a neighbour within 0.35 m, most do not
    assert set(weight.unique().tolist()) == {1.0, 5.0}
    tc.imitation.near_weight = 1.0
    *_, plain = _teacher_samples(None, adapter, drawn, WorldConfig(), SensingConfig(), tc, np.random.default_rng(0))
    assert (plain == 1.0).all()


def test_direction_weight_charges_a_short_action_pointing_the_wrong_way() -> None:
    """A teacher's scaled-down command (length 0.005): the squared error barely tells a network action pointing the
    other way from one along it; the direction term charges the wrong one ~2 x direction_weight more, the right one
    nothing; with direction_weight 0 the loss is the plain squared error, and a teacher at rest adds no term."""
    from stafpipe.learning.ppo import imitation_loss

    target = torch.tensor([[[0.005, 0.0], [0.0, 0.0]]])
    along, against = torch.tensor([[[0.004, 0.0], [0.0, 0.0]]]), torch.tensor([[[-0.004, 0.0], [0.0, 0.0]]])
    ones = torch.ones(1, 2)
    plain_along, plain_against = (
        imitation_loss(along, target, ones, 1.0, 0.0),
        imitation_loss(against, target, ones, 1.0, 0.0),
    )
    assert float(plain_against - plain_along) < 1e-4  # the squared error: 8e-5 / 2 robots apart
    assert float(plain_along) == pytest.approx(0.001**2 / 2)
    with_along, with_against = (
        imitation_loss(along, target, ones, 1.0, 0.5),
        imitation_loss(against, target, ones, 1.0, 0.5),
    )
    # the floor (1e-2) takes a 0.004-long action as 0.01 long: cosine -/+ 0.4, times 0.5, over 2 robots
    assert float(with_along - plain_along) == pytest.approx(0.5 * (1 - 0.4) / 2, rel=1e-4)
    assert float(with_against - plain_against) == pytest.approx(0.5 * (1 + 0.4) / 2, rel=1e-4)
    unit = torch.tensor([[[0.6, 0.8], [0.0, 0.0]]])
    assert float(imitation_loss(unit, unit, ones, 1.0, 0.5)) == pytest.approx(0.0, abs=1e-7)


def test_wall_copies_add_relabelled_near_wall_states() -> None:
    """`imitation.wall_copies=1`: each collected step gets a copy whose robots all have a wall point 0-0.4 m from
    their surface, at a random bearing, labelled with the teacher's (braking) action on that copy; the real samples
    are those of a run without copies."""
    from stafpipe.learning.config import RewardConfig
    from stafpipe.learning.ppo import _teacher_samples
    from stafpipe.learning.teachers import NEAR_WALL_GAP
    from stafpipe.registry import adapter_class

    im = ImitationConfig(epochs=1, teacher="avoiding", noise=0.0, wall_copies=1.0)
    tc = TrainPPOConfig(method="staf_planned", worlds=1, episode_steps=20, policy=PolicyConfig(hidden=16), imitation=im)
    corridor = load_named_scenario("corridor")
    adapter = adapter_class("staf_planned")(tc.policy, RewardConfig(), None, 2.0)
    drawn = [(corridor, np.array([[4.0, 6.0], [26.0, 6.0]]), 2.4)]
    own, _edge, _mask, label, _w = _teacher_samples(
        None, adapter, drawn, WorldConfig(), SensingConfig(), tc, np.random.default_rng(0)
    )
    tc.imitation.wall_copies = 0.0
    plain = _teacher_samples(None, adapter, drawn, WorldConfig(), SensingConfig(), tc, np.random.default_rng(0))
    assert len(own) == 2 * len(plain[0])
    real, copy = own[0::2], own[1::2]  # each step's own samples, then its copy
    assert torch.equal(real, plain[0]) and torch.equal(label[0::2], plain[3])
    wall = torch.linalg.norm(copy[..., 4:6].double(), dim=-1) - corridor.spec.robot.radius
    assert wall.min() >= -1e-6 and wall.max() <= NEAR_WALL_GAP + 1e-6
    # the teacher brakes on some copies (a wall ahead), so their labels differ from the free step towards the target
    braked = torch.linalg.norm(label[1::2] - label[0::2], dim=-1) > 1e-3
    assert braked.float().mean() > 0.1


def test_neighbour_copies_move_each_robots_nearest_neighbour_close_in_its_own_view() -> None:
    """`imitation.neighbour_copies`: in robot i's view (row i) its nearest sensed neighbour is moved to 0-0.4 m from
    its surface; nothing else changes, and a robot that senses no one keeps its view."""
    from stafpipe.learning.teachers import NEAR_WALL_GAP, near_neighbour_copy
    from stafpipe.sensing import Observation

    rng = np.random.default_rng(0)
    b, n, radius = 2, 4, 0.2
    pos = rng.uniform(0.0, 3.0, (b, n, 2))
    sensed = np.broadcast_to(~np.eye(n, dtype=bool), (b, n, n)).copy()
    sensed[1, 2, :] = False  # robot 2 of world 1 senses no one
    z = np.zeros
    rel = pos[:, None] - pos[:, :, None]
    obs = Observation(pos, z((b, n, 2)), z((b, n)), z((b, n, 2)), z((b, n, 2)), z((b, n)), sensed, rel,
                      z((b, n, n, 2)), z(b), z((b, 0, 4)), sensed)  # fmt: skip
    moved = near_neighbour_copy(obs, radius, rng)
    changed = (moved.rel_position != rel).any(-1)
    assert changed.sum(-1).tolist() == [[1, 1, 1, 1], [1, 1, 0, 1]]
    nearest = np.where(sensed, np.linalg.norm(rel, axis=-1), np.inf).argmin(-1)
    assert (changed.argmax(-1) == nearest)[sensed.any(-1)].all()
    gap = np.linalg.norm(moved.rel_position[changed], axis=-1) - 2 * radius
    assert gap.min() >= 0 and gap.max() <= NEAR_WALL_GAP


@pytest.mark.slow
def test_the_shipped_weights_are_the_best_on_held_out_maps(workdir) -> None:
    """With train_ppo.validation, policy.pt holds the weights of the iteration with the best validation success
    rate (ties: fewer collisions, then the earlier), chosen on maps it never trained on."""
    import torch

    from stafpipe.learning.ppo import best_iteration

    words = [*TINY, "train_ppo.iterations=3", "train_ppo.eval_every=1", "train_ppo.imitation.epochs=1",
             "train_ppo.imitation.rollouts=1", "train_ppo.validation=[doorway]", "train_ppo.validation_episodes=3",
             "train_ppo.formations=[circle]"]  # fmt: skip
    assert launch("train-ppo", words) == 0
    [run] = job_dirs(workdir)
    curves = pd.read_parquet(run / "learning_curves.parquet")
    assert curves["val/success_rate"].notna().all() and curves["val/collisions_per_episode"].notna().all()
    assert 0 <= curves["imitation/val_success_rate"][0] <= 1  # the warm start judged too: a candidate (iteration 0)
    chosen = best_iteration(curves.to_dict("records"))
    policy, made_by = load_policy(run / "policy.pt", "dgnn")
    assert made_by["selected_iteration"] == chosen and made_by["validation_maps"] == ["doorway"]
    state = torch.load(run / "ppo_state.pt", weights_only=True)
    assert state["best"]["iteration"] == chosen
    shipped = policy.state_dict()
    assert all(torch.equal(shipped[k], v) for k, v in state["best"]["policy"].items())
    assert launch("train-ppo", [*words[:-3], "train_ppo.validation=[corridor]"]) == 2  # corridor is trained on


def test_curriculum_variants_that_do_not_fit_their_map_are_left_out() -> None:
    from stafpipe.errors import StafpipeError
    from stafpipe.scenario import ScenarioConfig, TeamSpec, WorldBounds, build_scenario
    from stafpipe.scenario_pool import curriculum

    team = TeamSpec(n=4, formation="circle", spacing=1.0, start=[1.5, 1.5], goal=[6.5, 1.5], heading_deg=0.0)
    narrow = build_scenario(ScenarioConfig(name="narrow", world=WorldBounds(0, 0, 8, 3), obstacles=[], team=team))
    kept = curriculum([narrow], "formation", ["circle", "line"], "train_ppo.scenarios")  # a line of 4 is 3.4 m wide
    assert [s.spec.team.formation for s in kept] == ["circle"]
    with pytest.raises(StafpipeError, match="no scenario fits its team"):
        curriculum([narrow], "formation", ["line"], "train_ppo.scenarios")


def test_the_warm_started_network_is_a_candidate_for_the_shipped_weights() -> None:
    from stafpipe.learning.ppo import best_iteration

    scores = ((1, 0.8), (2, 0.9))
    rows = [{"iteration": k, "val/success_rate": sr, "val/collisions_per_episode": 0.5} for k, sr in scores]
    assert best_iteration(rows) == 2
    warm = {"imitation/val_success_rate": 0.95, "imitation/val_collisions_per_episode": 0.0}
    assert best_iteration([{**rows[0], **warm}, rows[1]]) == 0  # better than every PPO iteration: kept
    worse = {"imitation/val_success_rate": 0.9, "imitation/val_collisions_per_episode": 1.0}
    assert best_iteration([{**rows[0], **worse}, rows[1]]) == 2  # same SR, more contacts: the iteration wins


def test_drive_input_and_direction_weight_are_checked() -> None:
    from stafpipe.errors import StafpipeError

    with pytest.raises(StafpipeError, match=r"train_ppo.policy.drive_input"):
        TrainPPOConfig(method="dgnn", policy=PolicyConfig(drive_input=True)).check()
    with pytest.raises(StafpipeError, match=r"direction_weight"):
        TrainPPOConfig(imitation=ImitationConfig(direction_weight=-1.0)).check()
    TrainPPOConfig(method="staf_planned", policy=PolicyConfig(drive_input=True)).check()
    for gap in (-0.01, 0.35):  # below zero, or where the cap starts braking: never moves
        with pytest.raises(StafpipeError, match=r"train_ppo.imitation.stop_gap"):
            TrainPPOConfig(imitation=ImitationConfig(stop_gap=gap)).check()


def test_an_update_whose_losses_are_not_finite_stops_training_with_a_clear_error() -> None:
    """The update reads its losses once, after its minibatches (not at each, which waits for a GPU); a NaN there
    stops training rather than saving NaN weights."""
    from stafpipe.learning.rollout import collect
    from stafpipe.methods.dgnn.network import DGNNPolicy
    from stafpipe.registry import adapter_class
    from stafpipe.world import Worlds

    torch.manual_seed(0)
    corridor = load_named_scenario("corridor")
    tc = TrainPPOConfig(worlds=2, episode_steps=6, policy=PolicyConfig(hidden=16), minibatches=2, epochs=1)
    policy = DGNNPolicy(tc.policy)
    worlds = Worlds([corridor] * 2, SensingConfig())
    obs = worlds.reset([0, 1])
    adapter = adapter_class("dgnn")(tc.policy, tc.reward, None, 2.0)
    adapter.begin(ppo.teams_of([(corridor, np.array([[4.0, 6.0], [26.0, 6.0]]), 2.4)] * 2, worlds))
    ro, _ = collect(policy, adapter, worlds, obs, tc, 0.3)
    adv, ret = gae(ro.rewards, ro.values, ro.last_value, tc.gamma, tc.gae_lambda)
    opt = torch.optim.Adam(policy.parameters(), lr=tc.lr)
    stats = ppo.update(policy, opt, ro, adv, ret, tc, torch.Generator().manual_seed(0))
    assert all(math.isfinite(v) for v in stats.values()) and set(stats) >= {"losses/policy", "losses/clipfrac"}
    ret[0, 0, 0] = float("nan")
    with pytest.raises(StafpipeError, match="train_ppo: the PPO update's losses are not finite"):
        ppo.update(policy, opt, ro, adv, ret, tc, torch.Generator().manual_seed(0))


@pytest.mark.parametrize("message_layers", [1, 2])
def test_dgnn_messages_over_the_neighbour_list_are_the_dense_masked_ones(message_layers) -> None:
    """The CPU's edge-list trunk (the training and eval path) against the dense masked form (ONNX, GPU): the same
    outputs and gradients, with robots that have no neighbour and a world-step with none at all."""
    from stafpipe.learning.features import EDGE, OWN
    from stafpipe.methods.dgnn.network import DGNNPolicy

    torch.manual_seed(3)
    policy = DGNNPolicy(PolicyConfig(hidden=16, message_layers=message_layers))
    own, edge = torch.randn(5, 3, 6, OWN), torch.randn(5, 3, 6, 6, EDGE)
    mask = torch.rand(5, 3, 6, 6) < 0.35
    mask[0, 0] = False  # no pair in this world-step
    mask[1, 2, 4] = False  # robot 4 hears nobody
    grads = []
    for trunk in (policy._trunk_dense, policy._trunk_edges):
        policy.zero_grad()
        out = trunk(own, edge, mask)
        (out * torch.linspace(-1, 1, out.numel()).reshape(out.shape)).sum().backward()
        grads.append((out.detach(), [p.grad.clone() for p in policy.parameters() if p.grad is not None]))
    (dense, dense_grads), (edges, edge_grads) = grads
    assert dense.shape == edges.shape == (5, 3, 6, 16)
    torch.testing.assert_close(edges, dense, rtol=1e-6, atol=1e-6)
    assert len(dense_grads) == len(edge_grads)
    for a, b in zip(dense_grads, edge_grads, strict=True):
        torch.testing.assert_close(b, a, rtol=1e-5, atol=1e-6)
    silent = policy._trunk_edges(own, edge, torch.zeros_like(mask))
    heard = mask.any(-1)
    assert torch.equal(silent[~heard], edges[~heard])  # a robot that hears nobody: only its own features count
    assert not torch.isclose(silent[heard], edges[heard]).all(-1).any()  # one that hears a neighbour: they change it
    single = policy.act(own[0, 1], edge[0, 1], mask[0, 1])  # one team, no batch axis (the controller's call)
    torch.testing.assert_close(single, policy.actor(dense[0, 1]), rtol=1e-6, atol=1e-6)
