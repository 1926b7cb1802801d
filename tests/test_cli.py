from typer.testing import CliRunner

from stafpipe.cli import app

runner = CliRunner()
STAGES = ["generate", "generate-maps", "train-high", "train-ppo", "eval", "ablate", "plot", "run", "inspect"]


def test_help_lists_every_stage() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for stage in STAGES:
        assert stage in result.output


def test_every_stage_command_has_a_stage_function_and_a_primary_config() -> None:
    from stafpipe.launch import STAGE_FUNCTIONS, config_name, stage_function
    from stafpipe.paths import conf_dir

    assert set(STAGE_FUNCTIONS) == set(STAGES) - {"run", "inspect"}
    for stage in STAGE_FUNCTIONS:
        assert callable(stage_function(stage)) and (conf_dir() / f"{config_name(stage)}.yaml").is_file()


def test_generate_through_the_cli(workdir) -> None:
    result = runner.invoke(app, ["generate", "experiment=smoke", "data.instances=20", "seed=4"])
    assert result.exit_code == 0, result.output
    [parquet] = workdir.glob("outputs/generate/*/*/formations.parquet")
    assert (parquet.parent / "config.yaml").read_text().count("seed: 4") == 1
    assert (parquet.parent / ".hydra" / "config.yaml").is_file()
    assert (parquet.parent / "generate.log").is_file()
