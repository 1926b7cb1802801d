"""One path for learned methods: adapters shared by the PPO rollout and the evaluation controller, the imitation warm
start, the hand-made low levels of the ablation, and training on generated map directories."""

from __future__ import annotations

import dataclasses
import inspect
import math
import re

import numpy as np
import pytest
import torch

import stafpipe.learning.ppo as ppo
import stafpipe.learning.rollout as rollout
import stafpipe.stages.train_ppo as train_stage
from conftest import job_dirs
from staf_plans import scenario_with
from stafpipe.controllers import make_controller
from stafpipe.controllers.base import STOP_GAP, TeamInfo
from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.controllers.staf import StafMethodConfig
from stafpipe.episode import episode_context
from stafpipe.geometry import Geometry
from stafpipe.launch import launch
from stafpipe.learning.checkpoint import load_policy
from stafpipe.learning.config import ImitationConfig, PolicyConfig, TrainPPOConfig
from stafpipe.learning.teachers import AVOID_GAIN, SLIDE_MARGIN, off_the_wall, teacher_actions
from stafpipe.registry import adapter_class, learned_methods
from stafpipe.scenario import TeamSpec, WorldBounds, build_scenario
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig, Worlds


def test_trainer_has_no_method_name_branches() -> None:
    """A new learned method is a network, an adapter and a config: the trainer never names one."""
    for module in (ppo, rollout, train_stage):
        assert not re.search(r"""["'](staf_planned|staf|dgnn)["']""", inspect.getsource(module)), module.__name__
    assert learned_methods() == ["dgnn", "staf", "staf_planned"]


def _team(sc, worlds: Worlds, w: int = 0) -> TeamInfo:
    ctx, path = episode_context(sc, Geometry(sc), SensingConfig(), 0.3, 0.1)
    return TeamInfo(sc, worlds.pos[w].copy(), worlds.goal[w].copy(), sc.template(), path, ctx.passage_width)


def test_dgnn_is_guided_through_the_middle_of_a_passage_its_shortest_path_hugs() -> None:
    """A 45-degree corridor whose goal lies beyond its upper wall's end: the shortest path (TeamInfo.path) runs one
    radius from that wall, and DGNN guided along it slid on the wall (178 contacts an episode); the adapter guides
    along the centred path, which keeps near half the passage from both walls."""
    spec = dataclasses.replace(
        load_named_scenario("corridor").spec,
        world=WorldBounds(0, 0, 34, 34),
        obstacles=[
            {"polygon": [[8, 4], [26, 22], [26, 34], [0, 34], [0, 12]]},
            {"polygon": [[11, 0], [34, 0], [34, 19], [28.5, 20.5], [10.5, 2.5]]},
        ],
        team=TeamSpec(n=8, formation="wedge", spacing=1.0, start=(4.0, 4.0), goal=(30.0, 28.0), heading_deg=45.0),
    )
    sc = build_scenario(spec)
    worlds = Worlds([sc], SensingConfig())
    worlds.reset([0])
    team = _team(sc, worlds)
    adapter = adapter_class("dgnn")(PolicyConfig(), TrainPPOConfig().reward, None, 2.0)
    adapter.begin([team])
    geometry = Geometry.of(sc)
    inside = lambda path: path[(path[:, 0] > 12) & (path[:, 0] < 24)]  # noqa: E731  (within the corridor)
    shortest = geometry.clearance(inside(team.path)).min()
    guided = geometry.clearance(inside(adapter.paths[0])).min()
    assert shortest < sc.spec.robot.radius + 0.05  # the shortest path grazes the wall at one radius
    assert guided > team.passage_width / 2 - 0.1  # the guide keeps to the middle: 1.41 m from either wall


@pytest.mark.parametrize("method", ["dgnn", "staf_planned", "staf"])
def test_controller_acts_as_the_rollout_adapter_does(method) -> None:
    """The evaluation controller and the training rollout drive the same network through the same adapter: the
    controller's command equals the policy mean on the adapter's batched features, step after step."""
    sc = load_named_scenario("corridor")
    cfg = {
        "dgnn": lambda: __import__("stafpipe.methods.dgnn.method", fromlist=["x"]).DGNNConfig(),
        "staf_planned": lambda: StafMethodConfig(
            ensemble=[]
        ),  # the checkpoint alone (the default adds its partner run)
        "staf": lambda: __import__("stafpipe.methods.staf.method", fromlist=["x"]).StafConfig(),
    }[method]()
    ctrl = make_controller(cfg)
    worlds = Worlds([sc], SensingConfig())
    obs = worlds.reset([3])
    team = _team(sc, worlds)
    ctrl.reset(team)
    kind = adapter_class(method)
    adapter = kind(ctrl.policy.cfg, TrainPPOConfig().reward, getattr(cfg, kind.plan_key, None), 2.0)
    adapter.begin([team])
    for _ in range(60):
        f = adapter.step(obs, 0.1 if worlds.time[0] > 0 else 0.0).features
        with torch.no_grad():
            mean, _ = ctrl.policy(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
        command = ctrl.act(obs.world(0))
        expect = rollout.commands(mean.numpy(), worlds.heading, worlds.robot.max_speed)[0]
        assert np.allclose(command, expect, atol=1e-5)
        obs, _ = worlds.step(command[None])


def test_teachers_step_to_the_aim_and_the_avoiding_one_stops_short_of_a_wall() -> None:
    sc = load_named_scenario("corridor")
    worlds = Worlds([sc], SensingConfig())
    obs = worlds.reset([0])
    aim = np.zeros_like(obs.position)
    aim[..., 0] = 0.2  # 0.2 m ahead: the proportional step is 0.4 of top speed (gain 2)
    act = teacher_actions("proportional", aim, obs, 0.2, 1.0, 2.0, "holonomic")
    assert np.allclose(act[..., 0], 0.4) and np.allclose(act[..., 1], 0.0)
    worlds.pos[0, 0] = [12.0 - 0.2 - 0.05, 9.0]  # robot 0 5 cm in front of the upper wall block's face (x = 12)
    obs = worlds.observe()
    far = np.zeros_like(obs.position)
    far[..., 0] = 5.0
    capped = teacher_actions("avoiding", far, obs, 0.2, 1.0, 2.0, "holonomic")
    free = teacher_actions("proportional", far, obs, 0.2, 1.0, 2.0, "holonomic")
    assert free[0, 0, 0] == pytest.approx(1.0)
    gap = obs.obstacle_distance[0, 0]
    assert gap == pytest.approx(0.05, abs=1e-6)
    assert capped[0, 0] @ (obs.obstacle[0, 0] / np.linalg.norm(obs.obstacle[0, 0])) <= 2.0 * (gap - 0.02) + 1e-9
    # a stop gap of 0.04 m: the approach is capped at 2 x (0.05 - 0.04), exactly (the free step heads into the wall)
    wider = teacher_actions("avoiding", far, obs, 0.2, 1.0, 2.0, "holonomic", stop_gap=0.04)
    normal = obs.obstacle[0, 0] / np.linalg.norm(obs.obstacle[0, 0])
    assert wider[0, 0] @ normal == pytest.approx(2.0 * (gap - 0.04), abs=1e-6)
    assert capped[0, 0] @ normal == pytest.approx(2.0 * (gap - 0.02), abs=1e-6)
    # ORCA's teacher: 5 cm from the wall is inside its 0.1 m margin, so it may not approach the wall at all
    orca = teacher_actions("orca", far, obs, 0.2, 1.0, 2.0, "holonomic")
    assert orca[0, 0] @ (obs.obstacle[0, 0] / np.linalg.norm(obs.obstacle[0, 0])) <= 1e-6
    assert np.linalg.norm(orca[0, 0]) <= 1.0 + 1e-9


def test_sliding_teacher_aims_along_a_wall_at_its_margin() -> None:
    """A slot in the wall ahead: the `sliding` teacher aims at the line SLIDE_MARGIN in front of the wall, a slot beside
    it along the wall is kept, so the robot runs along the wall instead of pressing against it."""
    sc = load_named_scenario("corridor")
    worlds = Worlds([sc], SensingConfig(position_noise=0.0))
    worlds.reset([0])
    worlds.pos[0, 0] = [12.0 - 0.2 - 0.5, 9.0]  # robot 0 half a metre in front of the upper wall block's face (x = 12)
    obs = worlds.observe()
    normal = obs.obstacle[0, 0] / np.linalg.norm(obs.obstacle[0, 0])
    assert normal == pytest.approx([1.0, 0.0], abs=1e-6)
    aim = np.zeros_like(obs.position)
    aim[0, 0] = [2.0, 1.0]  # 1.5 m into the wall, 1 m along it
    moved = off_the_wall(aim, obs)
    assert moved[0, 0] == pytest.approx([0.5 - SLIDE_MARGIN, 1.0], abs=1e-6)
    assert np.array_equal(moved[0, 1:], aim[0, 1:])  # the others aim at their own robot: nothing to move
    along = aim.copy()
    along[0, 0] = [0.1, 1.0]
    assert np.array_equal(off_the_wall(along, obs), along)
    act = teacher_actions("sliding", aim, obs, 0.2, 1.0, 2.0, "holonomic")
    assert act[0, 0] @ normal == pytest.approx(2.0 * (0.5 - SLIDE_MARGIN) / np.hypot(2.0 * 0.35, 2.0), abs=1e-6)


def test_sliding_teacher_caps_where_a_differential_drive_moves_not_only_where_it_aims() -> None:
    """A differential-drive robot turning round towards an aim behind it drives along its heading meanwhile: with its
    heading towards a neighbour 0.05 m away and its aim away from it, the `sliding` teacher scales the command (same
    direction, so the same turn) until the forward motion's approach speed is within the cap; `avoiding`, which caps
    only the commanded velocity, does not."""
    sc = load_named_scenario("corridor")
    worlds = Worlds([sc], SensingConfig(position_noise=0.0))
    worlds.reset([0])
    bearing, heading, aim_dir, gap = -1.46, -2.2, 2.9, 0.05  # the seed-777 map-1 contact (docs/staf_planned.md)
    worlds.pos[0, 0] = [15.0, 6.0]
    worlds.pos[0, 1] = worlds.pos[0, 0] + (0.4 + gap) * np.array([math.cos(bearing), math.sin(bearing)])
    worlds.heading[0, 0] = heading
    obs = worlds.observe()
    aim = np.zeros_like(obs.position)
    aim[0, 0] = 2.0 * np.array([math.cos(aim_dir), math.sin(aim_dir)])
    h = np.array([math.cos(heading), math.sin(heading)])
    towards = np.array([math.cos(bearing), math.sin(bearing)])
    cap = AVOID_GAIN * (gap - STOP_GAP)

    def approach(kind: str, drive: str) -> tuple[float, np.ndarray]:
        act = teacher_actions(kind, aim, obs, 0.2, 1.0, 2.0, drive)
        world = rollout.commands(act, obs.heading, 1.0)[0, 0]  # the world-frame command, top speed 1 m/s
        return max(float(world @ h), 0.0) * float(h @ towards), world

    plain, plain_cmd = approach("avoiding", "diff_drive")
    capped, capped_cmd = approach("sliding", "diff_drive")
    assert plain_cmd @ towards < 0 < plain  # the command leaves the neighbour, the drive's motion approaches it
    assert capped == pytest.approx(cap, abs=1e-6)
    assert capped_cmd[0] * plain_cmd[1] - capped_cmd[1] * plain_cmd[0] == pytest.approx(0.0, abs=1e-9)
    assert capped_cmd @ plain_cmd > 0
    holonomic, _ = approach("sliding", "holonomic")
    assert holonomic == pytest.approx(plain, abs=1e-9)  # a holonomic robot moves as commanded: nothing to scale
    # `capped`: the same second cap, on `avoiding`'s command (this aim is not towards a wall, so it equals `sliding`)
    capped_only, capped_only_cmd = approach("capped", "diff_drive")
    assert capped_only == pytest.approx(cap, abs=1e-6) and np.allclose(capped_only_cmd, capped_cmd)


def test_capped_teacher_is_avoiding_on_holonomic_robots_and_never_moves_the_aim_off_a_wall() -> None:
    """`capped` adds only the differential drive's second cap to `avoiding`: on holonomic robots it is `avoiding`
    exactly, and a slot in the wall ahead is aimed at (braked for), not moved along the wall as `sliding` does."""
    sc = load_named_scenario("corridor")
    worlds = Worlds([sc], SensingConfig(position_noise=0.0))
    worlds.reset([0])
    worlds.pos[0, 0] = [12.0 - 0.2 - 0.5, 9.0]  # half a metre in front of the upper wall block's face (x = 12)
    obs = worlds.observe()
    aim = np.zeros_like(obs.position)
    aim[0, 0] = [2.0, 1.0]  # 1.5 m into the wall, 1 m along it
    expect = teacher_actions("avoiding", aim, obs, 0.2, 1.0, 2.0, "holonomic")
    assert np.array_equal(teacher_actions("capped", aim, obs, 0.2, 1.0, 2.0, "holonomic"), expect)

    def into_wall(kind: str) -> float:
        act = teacher_actions(kind, aim, obs, 0.2, 1.0, 2.0, "holonomic")
        return float(rollout.commands(act, obs.heading, 1.0)[0, 0] @ np.array([1.0, 0.0]))

    # 0.5 m from the wall nothing brakes yet: `capped` heads on at the slot, `sliding` at the margin line short of it
    assert into_wall("capped") > into_wall("sliding") + 0.1


@pytest.mark.slow  # two plans through the corridor: about 5 s on 2 cores
def test_imitation_teacher_aims_where_the_network_does_unless_privileged() -> None:
    """With `plan.adapt=nominal` the teacher drives to the plan's own nominal targets (what the network sees), unless
    `imitation.privileged`: then to a shadow plan's geometrically shrunk ones, which differ inside the corridor."""
    sc = scenario_with("corridor", "wedge")  # subteams of five: a wedge of five does not fit at 1 m spacing
    worlds = Worlds([sc], SensingConfig(position_noise=0.0), WorldConfig(start_noise=0.0))
    obs = worlds.reset([0])
    team, gaps = _team(sc, worlds), {}
    for privileged in (False, True):
        plan = PlanConfig(adapt="nominal", balance=True)
        adapter = adapter_class("staf_planned")(PolicyConfig(), TrainPPOConfig().reward, plan, 2.0)
        adapter.begin([team], privileged=privileged)
        pos, gap = obs.position.copy(), 0.0
        for _ in range(400):  # robots step straight to their targets (1 m/s, 0.1 s)
            target = adapter.step(obs._replace(position=pos), 0.1).targets
            gap = max(gap, float(np.abs(adapter.teacher_aim() - target).max()))
            d = target - pos
            pos = pos + d * np.minimum(1.0, 0.1 / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9))
        gaps[privileged] = gap
    assert gaps[False] == 0.0
    assert gaps[True] > 0.1  # the shadow plan shrank the subteams' spacing in the corridor


@pytest.mark.slow
def test_imitation_warm_start_fits_the_teacher(tmp_path) -> None:
    sc = load_named_scenario("corridor")
    ctx, path = episode_context(sc, Geometry(sc), SensingConfig(), 0.3, 0.1)
    tc = TrainPPOConfig(
        method="staf_planned",
        worlds=2,
        episode_steps=30,
        policy=PolicyConfig(hidden=32),
        imitation=ImitationConfig(epochs=200, rollouts=1, teacher="proportional", noise=0.0),
        # the first state is judged: on the path clipped at its start the team's targets already lead it by 0.5 m (a
        # state like those it trains on); on the extended path they start at the robots
        plan=PlanConfig(extend_path=False),
    )
    adapter = adapter_class("staf_planned")(tc.policy, tc.reward, tc.plan, 2.0)
    torch.manual_seed(0)
    policy = adapter.network(tc.policy)
    # exact positions and small start offsets, so the states judged are like the 60 it trains on
    exact, near = SensingConfig(position_noise=0.0), WorldConfig(start_noise=0.05)
    worlds = Worlds([sc, sc], exact, near)
    obs = worlds.reset([5, 6])
    adapter.begin([_team(sc, worlds, 0), _team(sc, worlds, 1)])
    f = adapter.step(obs, 0.0).features
    want = teacher_actions("proportional", adapter.teacher_aim() - obs.position, obs, 0.2, 1.0, 2.0, "holonomic")

    def error() -> float:
        with torch.no_grad():
            got = policy.act(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask)).numpy()
        return float(np.abs(got - want).mean())

    before = error()
    stats = ppo.imitate(policy, adapter, lambda rng, k: [(sc, path, ctx.passage_width)] * k, near, exact, tc, seed=0)
    assert stats["imitation/samples"] == 2 * 30 * 10
    assert error() < min(0.1, before / 4)  # the network now does roughly what the teacher does


@pytest.mark.slow
def test_staf_ablation_low_levels_run_and_are_refused_when_unknown(workdir) -> None:
    for low in ("proportional", "avoiding"):
        assert (
            launch(
                "eval",
                [
                    "method=staf_planned",
                    f"method.low_level={low}",
                    "method.plan.adapt=geometric",
                    "eval.episodes=1",
                    "scenario.time_limit=4",
                    f"eval.label={low}",
                ],
            )
            == 0
        )
    assert launch("eval", ["method=staf_planned", "method.low_level=magic", "eval.episodes=1"]) == 2
    assert launch("eval", ["method=dgnn", "method.low_level=magic", "eval.episodes=1"]) == 2
    assert launch("eval", ["method=staf_planned", "method.plan.adapt=squeeze", "eval.episodes=1"]) == 2
    runs = job_dirs(workdir)
    assert len(runs) == 2
    import pandas as pd

    labels = sorted(pd.read_parquet(r / "results.parquet").label.iloc[0] for r in runs)
    assert labels == ["avoiding", "proportional"]


@pytest.mark.slow  # 2-5 s on 2 cores: keeps `-m "not slow"` under 90 s
def test_a_checkpoint_trained_with_other_settings_is_refused_unless_allowed(workdir) -> None:
    from stafpipe.controllers.learned import checkpoint_mismatch

    # the shipped STAF policy was trained with two subteams: m=auto is another plan than the one it learned on
    assert (
        launch("eval", ["method=staf_planned", "method.plan.m=auto", "eval.episodes=1", "scenario.time_limit=2"]) == 2
    )
    assert not job_dirs(workdir)
    assert (
        launch(
            "eval",
            [
                "method=staf_planned",
                "method.plan.m=auto",
                "method.allow_mismatch=true",
                "eval.episodes=1",
                "scenario.time_limit=2",
            ],
        )
        == 0
    )
    # the hand-made low levels use no checkpoint: nothing to compare
    assert (
        launch(
            "eval",
            [
                "method=staf_planned",
                "method.low_level=proportional",
                "method.plan.adapt=nominal",
                "eval.episodes=1",
                "scenario.time_limit=2",
            ],
        )
        == 0
    )
    made_by = {"train_ppo": {"plan": {"m": "2", "adapt": "nominal"}}, "sensing": {"radius": 3.0}}
    differ = checkpoint_mismatch(StafMethodConfig(), made_by)
    assert differ == {"method.sensing_radius": (2.0, 3.0)}
    run = StafMethodConfig()
    run.plan.adapt = "geometric"
    assert set(checkpoint_mismatch(run, made_by)) == {"method.plan.adapt", "method.sensing_radius"}
    assert checkpoint_mismatch(run, {}) == {}  # an old checkpoint that recorded nothing is not refused


@pytest.mark.slow
@pytest.mark.parametrize(("top_speed", "recorded", "driven"), [(2.0, 1.0, 1.0), (0.5, 1.0, 0.5), (2.0, None, 2.0)])
def test_robots_faster_than_the_training_robots_are_driven_no_faster(tmp_path, top_speed, recorded, driven) -> None:
    """The network's action is a fraction of the top speed of the robots it was trained with (`made_by.max_speed`):
    robots of twice that speed get the trained robots' commands, slower robots their own fraction of it, and a
    record without the speed (written before it was kept) the robot's own top speed, as before."""
    from stafpipe.learning.checkpoint import save_policy
    from stafpipe.methods.dgnn.method import DGNNConfig

    base = load_named_scenario("corridor")
    sc = build_scenario(dataclasses.replace(base.spec, robot=dataclasses.replace(base.spec.robot, max_speed=top_speed)))
    policy, made_by = load_policy("", "dgnn")
    assert made_by["max_speed"] == 1.0  # the shipped network was trained on generated maps of 1 m/s robots
    if recorded is None:
        made_by.pop("max_speed")
    ctrl = make_controller(DGNNConfig(checkpoint=str(save_policy(tmp_path / "policy.pt", "dgnn", policy, made_by))))
    worlds = Worlds([sc], SensingConfig())
    obs = worlds.reset([3])
    team = _team(sc, worlds)
    ctrl.reset(team)
    adapter = adapter_class("dgnn")(ctrl.policy.cfg, TrainPPOConfig().reward, None, 2.0)
    adapter.begin([team])
    fastest = 0.0
    for _ in range(30):
        f = adapter.step(obs, 0.1 if worlds.time[0] > 0 else 0.0).features
        with torch.no_grad():
            mean, _ = ctrl.policy(torch.from_numpy(f.own), torch.from_numpy(f.edge), torch.from_numpy(f.mask))
        command = ctrl.act(obs.world(0))
        assert np.allclose(command, rollout.commands(mean.numpy(), worlds.heading, driven)[0], atol=1e-5)
        fastest = max(fastest, float(np.linalg.norm(command, axis=-1).max()))
        obs, _ = worlds.step(command[None])
    # the network asks for speed here; each robot-frame component is clipped to `driven`, so no more than sqrt(2) x it
    assert driven * 0.5 < fastest <= math.sqrt(2) * driven + 1e-9


@pytest.mark.slow  # a training on generated maps: about 16 s on 2 cores
def test_train_ppo_on_a_directory_of_generated_maps_records_them(workdir) -> None:
    assert (
        launch(
            "generate-maps",
            ["seed=5", "maps.count=2", "maps.team_sizes=[4,4]", "maps.drives=[holonomic]", "hydra.run.dir=maps"],
        )
        == 0
    )
    assert (
        launch(
            "train-ppo",
            [
                "train_ppo.method=staf_planned",
                "train_ppo.scenarios=[maps/maps]",
                "train_ppo.formations=[]",
                "train_ppo.iterations=1",
                "train_ppo.worlds=2",
                "train_ppo.episode_steps=6",
                "train_ppo.policy.hidden=16",
                "train_ppo.imitation.epochs=1",
                "hydra.run.dir=train",
            ],
        )
        == 0
    )
    _policy, made_by = load_policy(workdir / "train" / "policy.pt", "staf_planned")
    assert made_by["training_maps"] == sorted(made_by["training_maps"]) and len(made_by["training_maps"]) == 2
    assert all(name.startswith("gen5_") for name in made_by["training_maps"])
    assert made_by["max_speed"] == 1.0  # the generated maps' robots
    assert launch("train-ppo", ["train_ppo.scenarios=[maps/nothing_here]", "train_ppo.iterations=1"]) == 2


def test_plot_table_draws_labelled_variants_side_by_side(workdir) -> None:
    """`eval.label` keeps variants of one method apart: one table row each, no paper numbers beside a variant, and the
    levels figure (SR, collisions, CFI per map and variant)."""
    import pandas as pd

    row = {
        "method": "staf_planned",
        "formation": "line",
        "n": 10,
        "drive": "holonomic",
        "scenario": "doorway",
        "sr": 1.0,
        "tt": 30.0,
        "cfi_0.5": 0.8,
        "cfi_0.1": 0.7,
        "cfi_0.01": 0.7,
        "tt_ratio": 1.4,
        "collisions": 0.0,
        "eta": 1.3,
    }
    dirs = []
    for label, sr in (("a-no-learning", 0.5), ("b-learned", 1.0)):
        d = workdir / label
        d.mkdir()
        pd.DataFrame([{**row, "label": label, "sr": sr}] * 3).to_parquet(d / "results.parquet")
        dirs.append(str(d))
    assert launch("plot", ["plot.kind=table", f"plot.run_dirs=[{','.join(dirs)}]"]) == 0
    [run] = [d for d in job_dirs(workdir) if (d / "table.md").is_file()]
    text = (run / "table.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| STAF-planned (ours)")]
    assert len(rows) == 2 and "(ours) (a-no-learning)" in rows[0] and "(ours) (b-learned)" in rows[1]
    assert not any("[" in r for r in rows)  # the paper's numbers are not beside a variant
    assert (run / "levels.png").is_file()
    table = pd.read_csv(run / "table.csv")
    assert sorted(table.sr) == [0.5, 1.0]


@pytest.mark.parametrize("drive", ["holonomic", "diff_drive"])
def test_the_safety_layer_caps_the_approach_to_walls_and_robots(drive) -> None:
    """`method.approach_cap`: the shipped STAF's line through the corridor, stepped with the capped commands. Wherever a
    robot is within 0.35 m of the closest obstacle or of a robot it senses, it approaches it no faster than 2 x (gap -
    0.02 m), while the same controller without the layer, given the same observations, asks for more at some step."""
    base = load_named_scenario("corridor")
    spec = dataclasses.replace(
        base.spec,
        team=dataclasses.replace(base.spec.team, formation="line"),
        robot=dataclasses.replace(base.spec.robot, drive=drive),
    )
    sc = build_scenario(spec)
    capped = make_controller(StafMethodConfig(approach_cap=True))
    plain = make_controller(StafMethodConfig())
    worlds = Worlds([sc], SensingConfig(position_noise=0.0))
    obs = worlds.reset([1])
    team = _team(sc, worlds)
    capped.reset(team)
    plain.reset(team)
    near, exceeded = 0, 0
    for _ in range(260):
        one = obs.world(0)
        command, asked = capped.act(one), plain.act(one)
        towards = [(one.obstacle, one.obstacle_distance)]
        gaps = np.linalg.norm(one.rel_position, axis=-1) - 2 * sc.spec.robot.radius
        for j in range(sc.spec.team.n):
            towards.append((one.rel_position[:, j], np.where(one.neighbours[:, j], gaps[:, j], np.inf)))
        for vector, gap in towards:
            unit = vector / np.maximum(np.linalg.norm(vector, axis=-1, keepdims=True), 1e-9)
            close = gap < 0.35
            near += int(close.sum())
            assert ((command * unit).sum(-1)[close] <= AVOID_GAIN * (gap[close] - 0.02) + 1e-6).all()
            exceeded += int(((asked * unit).sum(-1)[close] > AVOID_GAIN * (gap[close] - 0.02) + 1e-6).sum())
        obs, _ = worlds.step(command[None])
    assert near > 0 and exceeded > 0
