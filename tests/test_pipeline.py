import pytest

from conftest import job_dirs
from stafpipe.errors import StafpipeError
from stafpipe.pipeline import run_pipeline


@pytest.mark.slow  # over 10 s on 2 cores
def test_smoke_runs_then_skips_then_forces(workdir, capsys) -> None:
    assert run_pipeline("smoke") == 0
    first = {d: (d / "stage.json").stat().st_mtime_ns for d in job_dirs(workdir)}
    assert len(first) == 8 and len(list(workdir.rglob("episodes/*.mcap"))) == 4
    assert len(list(workdir.rglob("*-plot-straight-*/trajectories_episode_0000.png"))) == 1
    capsys.readouterr()
    assert run_pipeline("smoke") == 0
    out = capsys.readouterr().out
    assert out.count("skipped") == 8
    assert {d: (d / "stage.json").stat().st_mtime_ns for d in job_dirs(workdir)} == first
    assert run_pipeline("smoke", force=True) == 0
    assert all((d / "stage.json").stat().st_mtime_ns != t for d, t in first.items())


def _write(workdir, text: str):
    path = workdir / "p.yaml"
    path.write_text(text)
    return str(path)


def test_failing_step_stops_the_pipeline(workdir, capsys) -> None:
    path = _write(
        workdir,
        "steps:\n"
        "  - {name: ok, stage: generate, overrides: [experiment=smoke]}\n"
        "  - {name: bad, stage: generate, overrides: [experiment=smoke, data.n_min=1]}\n"
        "  - {name: never, stage: generate, overrides: [experiment=smoke, seed=9]}\n",
    )
    assert run_pipeline(path) != 0
    assert "bad (generate): failed" in capsys.readouterr().out
    assert len(job_dirs(workdir)) == 1


def test_step_reference_and_bad_files(workdir) -> None:
    with pytest.raises(StafpipeError, match="stage"):
        run_pipeline(_write(workdir, "steps:\n  - {stage: fly}\n"))
    with pytest.raises(StafpipeError, match="not an earlier step"):
        run_pipeline(_write(workdir, "steps:\n  - {stage: generate, overrides: ['+x={steps.later.dir}']}\n"))
    with pytest.raises(StafpipeError, match="bad config"):
        run_pipeline(_write(workdir, "steps:\n  - {stage: generate, overrides: [wrong=1]}\n"))
    with pytest.raises(StafpipeError, match="no pipeline"):
        run_pipeline("does-not-exist")


def test_a_step_sweeps_its_axes_and_a_pattern_names_every_matching_step(workdir) -> None:
    from pathlib import Path

    from stafpipe.pipeline import load_pipeline, plan_pipeline

    path = _write(
        workdir,
        "steps:\n"
        "  - name: 'gen-{size}-{seed}'\n"
        "    stage: generate\n"
        "    overrides: [experiment=smoke, 'seed={seed}']\n"
        "    over:\n"
        "      size: {small: data.n_max=6, big: [data.n_max=8]}\n"
        "      seed: [1, 2]\n"
        "  - {name: last, stage: generate, overrides: [experiment=smoke, '+x=[{steps.gen-small-*.dir}]']}\n",
    )
    steps = load_pipeline(Path(path)).steps
    assert [s.name for s in steps] == ["gen-small-1", "gen-small-2", "gen-big-1", "gen-big-2", "last"]
    assert steps[2].overrides == ["experiment=smoke", "seed=1", "data.n_max=8"]
    plan = plan_pipeline(load_pipeline(Path(path)), workdir / "outputs", [])
    assert len({p[3] for p in plan[:4]}) == 4  # four configs, four hashes
    assert plan[-1][1][-1] == f"+x=[{plan[0][2]},{plan[1][2]}]"
    with pytest.raises(StafpipeError, match=r"must hold \{seed\}"):
        load_pipeline(Path(_write(workdir, "steps:\n  - {name: g, stage: generate, over: {seed: [1, 2]}}\n")))
    text = "steps:\n  - {name: 'g{seed}', stage: generate, overrides: ['+a=${seed}'], over: {seed: [1]}}\n"
    interpolated = load_pipeline(Path(_write(workdir, text)))
    assert interpolated.steps[0].overrides == ["+a=${seed}"]  # a Hydra interpolation is not an axis
    mixed = _write(
        workdir,
        "steps:\n  - {name: g-1, stage: generate, overrides: [experiment=smoke]}\n"
        "  - {name: e-1, stage: eval, overrides: [experiment=smoke]}\n"
        "  - {name: last, stage: plot, overrides: ['+x=[{steps.*-1.dir}]']}\n",
    )
    with pytest.raises(StafpipeError, match=r"matches steps of stages \['eval', 'generate'\]"):
        plan_pipeline(load_pipeline(Path(mixed)), workdir / "outputs", [])
    with pytest.raises(StafpipeError, match=r"over.seed: must be a non-empty list"):
        load_pipeline(Path(_write(workdir, "steps:\n  - {name: 'g{seed}', stage: generate, over: {seed: 3}}\n")))


@pytest.mark.slow  # over 5 s on 2 cores
def test_step_reruns_when_a_file_it_reads_changes(workdir, capsys) -> None:
    # The config hash is the same, but the map the step reads was edited: the old result must not be reused.
    from pathlib import Path

    scenario = workdir / "map.yaml"
    scenario.write_text((Path(__file__).parent / "data" / "s_example.yaml").read_text())
    path = _write(
        workdir,
        "steps:\n  - {name: e, stage: eval, overrides: [experiment=smoke, method=straight, "
        f"'scenario.path={scenario}', eval.episodes=1]}}\n",
    )
    assert run_pipeline(path) == 0
    assert run_pipeline(path) == 0
    assert capsys.readouterr().out.count("skipped") == 1
    scenario.write_text(scenario.read_text() + "\n# edited\n")
    assert run_pipeline(path) == 0
    assert capsys.readouterr().out.count("skipped") == 0


@pytest.mark.slow  # two runs, about 5 s
def test_a_users_config_dir_serves_a_stage_and_every_pipeline_step(workdir, capsys) -> None:
    from typer.testing import CliRunner

    from stafpipe.cli import app
    from stafpipe.paths import conf_dir

    mine = workdir / "my conf"  # a space in the path, as users' directories have
    (mine / "scenario").mkdir(parents=True)
    text = (conf_dir() / "scenario" / "doorway.yaml").read_text().replace("name: doorway", "name: my_door")
    (mine / "scenario" / "my_door.yaml").write_text(text)
    steps = (
        "steps:\n  - {name: door, stage: eval, overrides: [method=straight, scenario=my_door, eval.episodes=1, "
        "scenario.time_limit=1]}\n"
    )
    path = _write(workdir, "name: mine\n" + steps)
    without = CliRunner().invoke(app, ["run", path])
    assert without.exit_code == 2 and "scenario=my_door: no such scenario" in without.output
    assert CliRunner().invoke(app, ["run", path, "--config-dir", str(mine)]).exit_code == 0
    [run] = job_dirs(workdir)
    assert "name: my_door" in (run / "config.yaml").read_text()
    single = CliRunner().invoke(
        app,
        [
            "eval",
            "--config-dir",
            str(mine),
            "scenario=my_door",
            "method=straight",
            "eval.episodes=1",
            "scenario.time_limit=1",
        ],
    )
    assert single.exit_code == 0 and len(job_dirs(workdir)) == 2
    bad = CliRunner().invoke(app, ["run", path, "--config-dir", str(workdir / "nowhere")])
    assert bad.exit_code == 2 and "not a directory" in bad.output


@pytest.mark.slow  # composes the pipeline's seven steps: about 4-5 s
def test_staf_planned_train_is_the_recipe_of_both_shipped_runs(tmp_path) -> None:
    """`stafpipe run staf_planned_train`'s two train steps compose to the configs recorded beside `staf_planned.pt` and
    `staf_planned_seed1.pt`: the same seed, training, sensing, world and robot settings, and the same map steps (named
    by step; their directories' hashes change with any new config key). A plan setting added since is compared as the
    controller compares a checkpoint's record: only the keys the record has; a world setting added since must be at its
    default (`world.start_kick`: 0). A recipe edited without retraining fails here."""
    import re

    import yaml
    from omegaconf import OmegaConf

    from stafpipe.paths import package_dir
    from stafpipe.pipeline import find_pipeline, load_pipeline, plan_pipeline
    from stafpipe.world import WorldConfig

    steps = {
        s.name: cfg
        for s, _, _, _, cfg in plan_pipeline(load_pipeline(find_pipeline("staf_planned_train")), tmp_path, [])
    }

    def read(text: str) -> dict:
        return yaml.safe_load(re.sub(r"(/\d\d-[A-Za-z0-9_]+)-[0-9a-f]{10}/", r"\1/", text))

    for step, shipped in (("train", "staf_planned"), ("train_seed1", "staf_planned_seed1")):
        text = OmegaConf.to_yaml(steps[step], resolve=True).replace(f"{tmp_path.resolve()}/", "outputs/")
        ours = read(text)
        recorded = read((package_dir() / "checkpoints" / f"{shipped}.yaml").read_text())
        assert ours["train_ppo"]["scenarios"] == recorded["train_ppo"]["scenarios"]  # the step names, not hashes
        ours["train_ppo"]["plan"] = {k: ours["train_ppo"]["plan"][k] for k in recorded["train_ppo"]["plan"]}
        ours["train_ppo"].pop("subteaming")  # method=staf's rules, added since; staf_planned never reads them
        added = {k: v for k, v in ours["world"].items() if k not in recorded["world"]}  # world keys added since
        assert added == {k: getattr(WorldConfig(), k) for k in added}, (shipped, added)  # at their defaults (off)
        ours["world"] = {k: v for k, v in ours["world"].items() if k in recorded["world"]}
        for key in ("seed", "train_ppo", "sensing", "world", "robot"):
            assert ours[key] == recorded[key], (shipped, key)


@pytest.mark.slow  # composes the pipeline's steps
def test_staf_train_is_the_recipe_of_the_shipped_staf(tmp_path) -> None:
    """`stafpipe run staf_train`'s train step composes to the config recorded beside `staf.pt` (map steps named by
    step): a recipe edited without retraining fails here."""
    import re

    import yaml
    from omegaconf import OmegaConf

    from stafpipe.paths import package_dir
    from stafpipe.pipeline import find_pipeline, load_pipeline, plan_pipeline

    steps = {s.name: cfg for s, _, _, _, cfg in plan_pipeline(load_pipeline(find_pipeline("staf_train")), tmp_path, [])}

    def read(text: str) -> dict:
        return yaml.safe_load(re.sub(r"(/\d\d-[A-Za-z0-9_]+)-[0-9a-f]{10}/", r"\1/", text))

    ours = read(OmegaConf.to_yaml(steps["train"], resolve=True).replace(f"{tmp_path.resolve()}/", "outputs/"))
    recorded = read((package_dir() / "checkpoints" / "staf.yaml").read_text())
    for key in ("seed", "train_ppo", "sensing", "world", "robot"):
        assert ours[key] == recorded[key], key
