"""Sweeps go through Hydra's launcher plugins: each job its own directory with its own config."""

import pytest
from omegaconf import OmegaConf

from conftest import job_dirs
from stafpipe.launch import launch

SMALL = ["experiment=smoke", "data.instances=10"]


def _configs(root):
    return sorted(
        (OmegaConf.load(d / ".hydra" / "config.yaml").formation.type, OmegaConf.load(d / ".hydra" / "config.yaml").seed)
        for d in job_dirs(root)
    )


@pytest.mark.parametrize(
    "launcher",
    [
        pytest.param([], marks=pytest.mark.slow),  # about 6.5 s on 2 cores
        pytest.param(["hydra/launcher=local", "hydra.launcher.n_jobs=2"], marks=pytest.mark.slow),
    ],
    ids=["basic", "joblib"],
)
def test_two_by_two_multirun_gives_four_jobs(workdir, launcher) -> None:
    code = launch("generate", ["-m", *launcher, "formation=circle,wedge", "seed=1,2", *SMALL])
    assert code == 0
    assert _configs(workdir / "outputs" / "multirun") == [("circle", 1), ("circle", 2), ("wedge", 1), ("wedge", 2)]
    for d in job_dirs(workdir / "outputs" / "multirun"):
        assert (d / "formations.parquet").is_file()


@pytest.mark.slow  # over 10 s on 2 cores
def test_submitit_local_two_jobs(workdir) -> None:
    code = launch("generate", ["-m", "hydra/launcher=submitit_local", "seed=5,6", *SMALL])
    assert code == 0
    dirs = job_dirs(workdir / "outputs" / "multirun")
    assert [OmegaConf.load(d / "config.yaml").seed for d in dirs] == [5, 6]


@pytest.mark.slow  # a local Ray cluster starts: about 30 s
def test_ray_sweep_of_two_eval_jobs_gathers_into_one_table(workdir) -> None:
    pytest.importorskip("hydra_plugins.hydra_ray_launcher", reason="needs the ray extra: pip install '.[ray]'")
    short = ["method=straight", "scenario=corridor", "scenario.time_limit=2", "eval.episodes=1"]
    assert launch("eval", ["-m", "hydra/launcher=ray", *short, "seed=1,2"]) == 0
    dirs = job_dirs(workdir / "outputs" / "multirun")
    assert sorted(OmegaConf.load(d / "config.yaml").seed for d in dirs) == [1, 2]
    assert all((d / "results.csv").is_file() and list(d.glob("episodes/*.mcap")) for d in dirs)
    # a sweep's job directories are read by `plot table` exactly as a pipeline's steps are
    assert launch("plot", ["plot.kind=table", f"plot.run_dirs=[{','.join(map(str, dirs))}]"]) == 0
    [table_dir] = [d for d in job_dirs(workdir / "outputs") if (d / "table.csv").is_file()]
    assert "straight" in (table_dir / "table.md").read_text()


@pytest.mark.slow  # two sweeps of four maps, one in two processes; each map's path grid about 2 s: 30-40 s
def test_a_directory_of_maps_is_one_sweep_with_the_same_results_in_parallel(workdir) -> None:
    import pandas as pd

    maps = workdir / "maps"
    maps.mkdir()
    for k in range(4):
        (maps / f"m{k}.yaml").write_text(
            f"name: m{k}\nworld: {{xmin: 0, ymin: -2.5, xmax: 6, ymax: 2.5}}\ntime_limit: 3\n"
            f"team: {{n: {3 + k}, formation: line, spacing: 0.5, start: [1.5, 0], goal: [4.5, 0]}}\n"
        )
    common = ["eval", "-m", "method=straight", f"scenario.path={maps}", "eval.episodes=1"]
    assert launch(*common[:1], [*common[1:], f"hydra.sweep.dir={workdir / 'serial'}"]) == 0
    local = ["hydra/launcher=local", "hydra.launcher.n_jobs=2", f"hydra.sweep.dir={workdir / 'par'}"]
    assert launch(*common[:1], [*common[1:], *local]) == 0
    for j in range(4):
        serial, parallel = (pd.read_parquet(workdir / d / str(j) / "results.parquet") for d in ("serial", "par"))
        assert serial.equals(parallel) and serial["scenario"].iloc[0] == f"m{j}" and serial["n"].iloc[0] == 3 + j
    assert launch("plot", ["plot.kind=table", f"plot.run_dir={workdir / 'par'}"]) == 0  # one table of the four
    [table] = [d for d in job_dirs(workdir / "outputs" / "plot") if (d / "table.csv").is_file()]
    assert sorted(pd.read_csv(table / "table.csv")["scenario"]) == ["m0", "m1", "m2", "m3"]


@pytest.mark.slow  # two tiny trainings: about 20 s
def test_optuna_search_reads_each_jobs_objective(workdir) -> None:
    pytest.importorskip("hydra_plugins.hydra_optuna_sweeper", reason="needs the optuna extra: pip install '.[optuna]'")
    import json

    args = ["-m", "hydra/sweeper=ppo_search", "hydra.sweeper.n_trials=2", "experiment=smoke", "train_ppo.iterations=1"]
    assert launch("train-ppo", args) == 0
    [sweep] = (workdir / "outputs" / "multirun" / "train-ppo").glob("*/*")
    jobs = job_dirs(sweep)
    assert len(jobs) == 2
    values = [json.loads((d / "objective.json").read_text())["value"] for d in jobs]
    lrs = {float(OmegaConf.load(d / "config.yaml").train_ppo.lr) for d in jobs}
    assert len(lrs) == 2 and all(1e-5 <= lr <= 1e-3 for lr in lrs)  # two proposals from the search space
    result = OmegaConf.load(sweep / "optimization_results.yaml")
    assert result.best_value == max(values)


def test_the_objective_is_the_validation_score_of_the_kept_weights() -> None:
    from stafpipe.stages.train_ppo import kept_score

    warm = {"imitation/val_success_rate": 0.5, "imitation/val_collisions_per_episode": 1.0}
    history = [
        {"iteration": 1, "charts/success_rate": 0.1, **warm},
        {"iteration": 2, "charts/success_rate": 0.2, "val/success_rate": 0.7, "val/collisions_per_episode": 0.0},
        {"iteration": 3, "charts/success_rate": 0.9, "val/success_rate": 0.6, "val/collisions_per_episode": 0.0},
    ]
    assert kept_score(history) == {
        "name": "val/success_rate of iteration 2 (kept)",
        "value": 0.7,
        "direction": "maximize",
    }
    assert kept_score(history[:1])["value"] == 0.5  # only the warm start was judged: it is kept
    assert kept_score([{"iteration": 1, "charts/success_rate": 0.3}])["value"] == 0.3  # no validation
