from typer.testing import CliRunner

from stafpipe.cli import app

runner = CliRunner()
STAGES = ["generate", "train-high", "train-ppo", "eval", "ablate", "plot", "run", "inspect"]


def test_help_lists_every_stage() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for stage in STAGES:
        assert stage in result.output


def test_unimplemented_stage_exits_2_with_one_line() -> None:
    result = runner.invoke(app, ["train-ppo", "seed=1"])  # filled by the PPO issue
    assert result.exit_code == 2
    assert "not implemented yet" in result.output


def test_generate_through_the_cli(workdir) -> None:
    result = runner.invoke(app, ["generate", "experiment=smoke", "data.instances=20", "seed=4"])
    assert result.exit_code == 0, result.output
    [parquet] = workdir.glob("outputs/generate/*/*/formations.parquet")
    assert (parquet.parent / "config.yaml").read_text().count("seed: 4") == 1
    assert (parquet.parent / ".hydra" / "config.yaml").is_file()
    assert (parquet.parent / "generate.log").is_file()
