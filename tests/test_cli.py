from typer.testing import CliRunner

from stafpipe.cli import app

runner = CliRunner()
STAGES = ["generate", "generate-maps", "train-high", "train-ppo", "eval", "ablate", "plot", "run", "inspect", "export"]


def test_help_lists_every_stage() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for stage in STAGES:
        assert stage in result.output


def test_every_stage_explains_its_overrides_groups_and_examples() -> None:
    from stafpipe.launch import STAGE_FUNCTIONS

    for stage in STAGE_FUNCTIONS:
        out = runner.invoke(app, [stage, "--help"]).output
        assert "Trailing words are Hydra overrides" in out and "did-you-mean" in out, stage
        methods = "method: cezayirli, dgnn, lf, onnx, staf, staf_planned, straight, zhu"
        assert methods in out and "base" not in out, stage
        assert "formation: circle, line" in out and "robot: diff_drive, holonomic" in out, stage
        assert "scenario: bollards, bridge" in out and "experiment: " in out, stage
        examples = out.split("Examples:")[1].strip().splitlines()
        assert len(examples) == 2 and all(e.strip().startswith(f"stafpipe {stage} ") for e in examples), stage
    for command in [*STAGES, None]:
        out = runner.invoke(app, [command, "--help"] if command else ["--help"]).output
        assert "<bool>" not in out, command
    plot = runner.invoke(app, ["plot", "--help"]).output
    for kind in ("trajectories", "partitions", "training", "connectivity", "regions", "timing", "table"):
        assert kind in plot.split("Trailing words")[0], kind


def test_every_stage_command_has_a_stage_function_and_a_primary_config() -> None:
    from stafpipe.launch import STAGE_FUNCTIONS, config_name, stage_function
    from stafpipe.paths import conf_dir

    assert set(STAGE_FUNCTIONS) == set(STAGES) - {"run", "inspect", "export"}
    for stage in STAGE_FUNCTIONS:
        assert callable(stage_function(stage)) and (conf_dir() / f"{config_name(stage)}.yaml").is_file()


def test_generate_through_the_cli(workdir) -> None:
    result = runner.invoke(app, ["generate", "experiment=smoke", "data.instances=20", "seed=4"])
    assert result.exit_code == 0, result.output
    [parquet] = workdir.glob("outputs/generate/*/*/formations.parquet")
    assert (parquet.parent / "config.yaml").read_text().count("seed: 4") == 1
    assert (parquet.parent / ".hydra" / "config.yaml").is_file()
    assert (parquet.parent / "generate.log").is_file()
