"""`stafpipe export`: the ONNX file of each shipped network gives torch's output on observations recorded from the
harness (onnxruntime, max abs difference <= 1e-5), for teams of other sizes than the export's example."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from stafpipe.cli import app

ort = pytest.importorskip("onnxruntime")  # the `onnx` extra (installed with `test`)


def recorded_features(method: str, n: int, steps: int = 30) -> list[tuple[np.ndarray, ...]]:
    """(own, edge, mask) of one world, as the method's adapter computes them in eval, at every 10th step of an
    episode on the corridor driven towards the adapter's aim (robots close up, neighbours come and go)."""
    import dataclasses

    from stafpipe.learning.checkpoint import load_policy
    from stafpipe.learning.config import RewardConfig
    from stafpipe.learning.ppo import teams_of
    from stafpipe.learning.rollout import commands
    from stafpipe.learning.teachers import teacher_actions
    from stafpipe.registry import adapter_class
    from stafpipe.scenario import build_scenario
    from stafpipe.scenario_pool import load_named_scenario, path_and_width
    from stafpipe.sensing import SensingConfig
    from stafpipe.world import WorldConfig, Worlds

    base = load_named_scenario("corridor")
    scenario = build_scenario(dataclasses.replace(base.spec, team=dataclasses.replace(base.spec.team, n=n)))
    policy, made_by = load_policy("", method)
    plan = made_by.get("train_ppo", {}).get("plan")
    from stafpipe.controllers.plan_config import PlanConfig

    adapter = adapter_class(method)(policy.cfg, RewardConfig(), PlanConfig(**plan) if plan else PlanConfig(), 2.0)
    world_cfg = WorldConfig()
    worlds = Worlds([scenario], SensingConfig(), world_cfg)
    obs = worlds.reset([3])
    adapter.begin(teams_of([(scenario, *path_and_width(scenario))], worlds))
    out = []
    for t in range(steps):
        f = adapter.step(obs, world_cfg.control_dt).features
        if t % 10 == 0:
            out.append((f.own[0], f.edge[0], f.mask[0]))
        act = teacher_actions(
            "avoiding",
            adapter.teacher_aim() - obs.position,
            obs,
            worlds.robot.radius,
            worlds.robot.max_speed,
            2.0,
            worlds.robot.drive,
        )
        obs, _ = worlds.step(commands(act, worlds.heading, worlds.robot.max_speed))
    return out


@pytest.mark.slow  # three exports, about 10 s
@pytest.mark.parametrize("method", ["staf_planned", "dgnn"])
def test_policy_onnx_matches_torch_on_recorded_observations(workdir, method: str) -> None:
    from stafpipe.learning.checkpoint import ensemble_paths, load_policy

    result = CliRunner().invoke(app, ["export", method])
    assert result.exit_code == 0, result.output
    session = ort.InferenceSession(str(workdir / "outputs" / "export" / f"{method}.onnx"))
    assert [i.name for i in session.get_inputs()] == ["own", "edge", "mask"]
    # the shipped policy as eval runs it: STAF's two runs averaged (method.ensemble unset), DGNN's one
    runs = [load_policy(path, method)[0] for path in ["", *ensemble_paths("", None, method)]]
    assert len(runs) == {"staf_planned": 2, "dgnn": 1}[method]
    worst = 0.0
    for n in (4, 10, 13):
        for own, edge, mask in recorded_features(method, n):
            got = session.run(["action"], {"own": own, "edge": edge, "mask": mask})[0]
            with torch.no_grad():
                x = (torch.from_numpy(own), torch.from_numpy(edge), torch.from_numpy(mask))
                want = torch.stack([run.act(*x) for run in runs]).mean(0).numpy()
            assert got.shape == (n, 2) and np.abs(want).max() > 0.05  # the policy does move the robots
            worst = max(worst, float(np.abs(got - want).max()))
    assert worst <= 1e-5


@pytest.mark.slow
def test_graph_cut_onnx_matches_the_sparse_torch_network(workdir) -> None:
    from stafpipe.highlevel.checkpoint import load_checkpoint
    from stafpipe.highlevel.graphs import Team, collate, team_graph

    out = workdir / "cut.onnx"
    assert CliRunner().invoke(app, ["export", "high", "--output", str(out)]).exit_code == 0
    session = ort.InferenceSession(str(out))
    model, _ = load_checkpoint()
    cfg = model.cfg
    rng = np.random.default_rng(5)
    for n, m in ((5, 2), (10, 3), (17, 4), (8, 1)):
        pos = rng.uniform(0, 4, (n, 2))
        team = Team(pos, pos + [20.0, 1.0], m)
        graph = team_graph(team, cfg.features, cfg.radius)
        adjacency = np.zeros((n, n), dtype=bool)
        adjacency[graph.edges[1], graph.edges[0]] = True
        got = session.run(
            ["assignment"], {"x": graph.x.astype(np.float32), "adjacency": adjacency, "m": np.array(m, dtype=np.int64)}
        )[0]
        with torch.no_grad():
            want = model(collate([graph], [m])).numpy()
        assert got.shape == (n, cfg.m_max)
        assert np.abs(got - want).max() <= 1e-5
        assert np.allclose(got[:, m:], 0.0) and np.allclose(got.sum(1), 1.0, atol=1e-5)


def test_export_refuses_an_unknown_network_and_a_missing_checkpoint(workdir) -> None:
    bad = CliRunner().invoke(app, ["export", "ppo"])
    assert bad.exit_code == 2 and "network must be one of" in bad.output
    missing = CliRunner().invoke(app, ["export", "dgnn", "--checkpoint", "nowhere.pt"])
    assert missing.exit_code == 2 and "nowhere.pt" in missing.output
    assert not (workdir / "outputs" / "export").exists()


def test_a_drive_input_network_is_exported_with_the_drive_flag_in_its_own_state() -> None:
    from stafpipe.export_onnx import PolicyMean, example_inputs
    from stafpipe.learning.config import PolicyConfig
    from stafpipe.learning.features import STAF_OWN
    from stafpipe.learning.staf_net import StafPolicy

    module = PolicyMean(StafPolicy(PolicyConfig(hidden=8, drive_input=True)))
    inputs = example_inputs("staf_planned", module)
    assert inputs["own"].shape[-1] == STAF_OWN + 1
    assert module(**inputs).shape == (5, 2)


def test_the_exported_policy_is_the_one_eval_runs_and_bad_ensembles_are_refused(workdir) -> None:
    """The module behind the file: the shipped STAF with its partner run (as `method.ensemble` unset), a user's
    checkpoint or `--no-ensemble` alone; a member of another network, or an ensemble for the graph cut, refused."""
    from stafpipe.errors import StafpipeError
    from stafpipe.export_onnx import load_network
    from stafpipe.learning.checkpoint import load_policy, save_policy
    from stafpipe.learning.config import PolicyConfig
    from stafpipe.learning.staf_net import StafPolicy

    own, edge, mask = recorded_features("staf_planned", 6, steps=11)[-1]
    x = (torch.from_numpy(own), torch.from_numpy(edge), torch.from_numpy(mask))
    first, second = (load_policy(p, "staf_planned")[0] for p in ("", "shipped:staf_planned_seed1"))
    with torch.no_grad():
        pair, alone = (torch.stack([r.act(*x) for r in runs]).mean(0) for runs in ([first, second], [first]))
        shipped, made_by = load_network("staf_planned")
        assert torch.equal(shipped(*x), pair) and not torch.allclose(pair, alone, atol=1e-3)
        assert [m["path"] for m in made_by["ensemble"]] == ["shipped:staf_planned_seed1"]
        assert made_by["ensemble"][0]["made_by"]["seed"] == 1
        assert torch.equal(load_network("staf_planned", ensemble=[])[0](*x), alone)
        assert torch.equal(
            load_network("staf_planned", "shipped:staf_planned")[0](*x), alone
        )  # a named checkpoint: no partners
    save_policy(workdir / "small.pt", "staf_planned", StafPolicy(PolicyConfig(hidden=32)), {})
    with pytest.raises(StafpipeError, match=r"ensemble\[0\].*another network"):
        load_network("staf_planned", ensemble=[str(workdir / "small.pt")])
    result = CliRunner().invoke(app, ["export", "high", "--ensemble", "shipped:staf_planned_seed1"])
    assert result.exit_code == 2 and "not the deep graph cut" in result.output
    result = CliRunner().invoke(app, ["export", "staf_planned", "--ensemble", "x.pt", "--no-ensemble"])
    assert result.exit_code == 2 and "together" in result.output
