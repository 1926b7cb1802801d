"""The `stafpipe` command: one subcommand per stage. Trailing arguments are Hydra overrides and flags
(`-m` for a sweep, `--cfg job`, `--info`), passed to the stage as to any Hydra application."""

from __future__ import annotations

from collections.abc import Callable

import typer

from stafpipe.errors import StafpipeError

app = typer.Typer(
    help="stafpipe: subteaming and adaptive formation control experiments. "
    "Each stage takes Hydra overrides, e.g. `stafpipe generate formation=wedge seed=3`, or `-m` to sweep.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,  # plain help: no type tags such as <bool> in option rows, epilogs kept as written
)
_HYDRA_ARGS = {"allow_extra_args": True, "ignore_unknown_options": True}
GROUPS = ("method", "scenario", "formation", "robot", "experiment")
EXAMPLES = {
    "generate": [
        "stafpipe generate formation=wedge seed=3 data.instances=5000",
        "stafpipe generate -m formation=circle,wedge,line seed=1,2",
    ],
    "generate-maps": [
        "stafpipe generate-maps seed=7 maps.count=20",
        "stafpipe generate-maps maps.count=5 'maps.drives=[diff_drive]'",
    ],
    "train-high": ["stafpipe train-high experiment=smoke", "stafpipe train-high seed=2 'data.mix=[wedge,line]'"],
    "train-ppo": [
        "stafpipe train-ppo train_ppo.method=dgnn train_ppo.iterations=50",
        "stafpipe train-ppo experiment=staf_train 'train_ppo.scenarios=[outputs/generate-maps/DATE/TIME/maps]'",
    ],
    "eval": [
        "stafpipe eval method=staf scenario=bridge formation=wedge eval.episodes=20",
        "stafpipe eval -m hydra/launcher=local method=staf_planned,dgnn,lf scenario=corridor",
    ],
    "ablate": ["stafpipe ablate ablate.study=subteam_count", "stafpipe ablate ablate.study=noise seed=2"],
    "plot": [
        "stafpipe plot trajectories outputs/eval/DATE/TIME",
        "stafpipe plot table plot.run_dirs='[outputs/eval/A,outputs/eval/B]'",
    ],
}


def _overrides_help() -> str:
    """The part of every stage's help that is the same for all: overrides, config groups and their options (the
    group directories are listed once per process, not once per stage)."""
    from stafpipe.paths import conf_dir

    lines = [
        "\b",
        "Trailing words are Hydra overrides: key=value (e.g. eval.episodes=20), group=option (below),",
        "-m to sweep comma-separated values, --cfg job to print the composed config and run nothing.",
        "A misspelled key or option is refused with a did-you-mean (exit code 2).",
        "",
        "\b",
        "Config groups:",
    ]
    for group in GROUPS:
        options = sorted(p.stem for p in (conf_dir() / group).glob("*.yaml") if not p.stem.startswith("base"))
        lines.append(f"  {group}: {', '.join(options)}")
    return "\n".join(lines)


_OVERRIDES_HELP = _overrides_help()


def _epilog(stage: str) -> str:
    """What a stage's help says after its options: overrides, config groups and their options, two examples."""
    return "\n".join([_OVERRIDES_HELP, "", "\b", "Examples:", *(f"  {e}" for e in EXAMPLES[stage])])


def _stage(stage: str, overrides: list[str]) -> None:
    from stafpipe.launch import launch

    raise typer.Exit(launch(stage, overrides))


@app.command("generate", context_settings=_HYDRA_ARGS, epilog=_epilog("generate"))
def generate(ctx: typer.Context) -> None:
    """Generate the synthetic formation dataset (STAF Appendix C) as Parquet + CSV."""
    _stage("generate", ctx.args)


@app.command("generate-maps", context_settings=_HYDRA_ARGS, epilog=_epilog("generate-maps"))
def generate_maps(ctx: typer.Context) -> None:
    """Generate seeded procedural training maps (corridors, doorways, bends, gaps, bollards, fields) as scenario
    YAMLs."""
    _stage("generate-maps", ctx.args)


@app.command("train-high", context_settings=_HYDRA_ARGS, epilog=_epilog("train-high"))
def train_high(ctx: typer.Context) -> None:
    """Train STAF's high level (deep graph cut for subteaming) on a generated dataset."""
    _stage("train-high", ctx.args)


@app.command("train-ppo", context_settings=_HYDRA_ARGS, epilog=_epilog("train-ppo"))
def train_ppo(ctx: typer.Context) -> None:
    """Train a navigation policy (STAF intermediate + low level, or DGNN) with PPO."""
    _stage("train-ppo", ctx.args)


@app.command("eval", context_settings=_HYDRA_ARGS, epilog=_epilog("eval"))
def eval_(ctx: typer.Context) -> None:
    """Evaluate a method on a scenario over seeded episodes: results table + one MCAP file per episode."""
    _stage("eval", ctx.args)


@app.command("ablate", context_settings=_HYDRA_ARGS, epilog=_epilog("ablate"))
def ablate(ctx: typer.Context) -> None:
    """Graph-cut studies: loss terms (STAF Fig. 7), subteam count (Fig. 9), noise (Fig. 14), classical partitions."""
    _stage("ablate", ctx.args)


@app.command("plot", context_settings=_HYDRA_ARGS, epilog=_epilog("plot"))
def plot(
    ctx: typer.Context,
    kind: str = typer.Argument(
        None,
        help="What to draw: video (eval run or .mcap file: MP4 + GIF per episode), trajectories (eval run), "
        "partitions (ablate run), training (train-ppo/-high run), "
        "connectivity (Cezayirli eval run), regions (Zhu eval run), timing (Zhu runs: Table I), table (STAF Tables 1-2 "
        "from plot.run_dirs=[...]).",
    ),
    run_dir: str = typer.Argument(None, help="The run directory to draw from (e.g. an eval run; video: or a .mcap)."),
) -> None:
    """Draw figures from a run directory, e.g. `stafpipe plot trajectories outputs/eval/DATE/TIME`."""
    # The two positionals are sugar for plot.kind= and plot.run_dir=; anything that looks like an override is one.
    given = [a for a in (kind, run_dir) if a is not None]
    positional = [a for a in given if "=" not in a and not a.startswith("-")]
    overrides = [a for a in given if a not in positional]
    keys = ["plot.kind", "plot.run_dir"]
    _stage("plot", [f"{k}={_quote(v)}" for k, v in zip(keys, positional, strict=False)] + overrides + ctx.args)


def _quote(value: str) -> str:
    # A path with characters Hydra's override grammar treats specially (spaces, commas, brackets) is quoted.
    return value if all(c.isalnum() or c in "/._-~" for c in value) else "'" + value.replace("'", "\\'") + "'"


def _fs_fault_exit(exc: OSError) -> None:
    """A file-system fault (disk full, read-only, no permission) as one line and exit 2; anything else re-raised."""
    from stafpipe.launch import fs_fault

    fault = fs_fault(exc)
    if fault is None:
        raise exc
    typer.echo(f"error: {fault}", err=True)
    raise typer.Exit(2) from None


def _exit_with(work: Callable[[], int]) -> None:
    """Exit with the code `work()` returns; a StafpipeError is one line and exit code 2, a file-system fault too."""
    try:
        code = work()
    except StafpipeError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    except OSError as exc:
        _fs_fault_exit(exc)
    raise typer.Exit(code)


@app.command()
def run(
    pipeline: str = typer.Argument(..., help="A name in pipelines/ (e.g. smoke) or a path to a pipeline YAML."),
    force: bool = typer.Option(False, "--force", help="Run every step, even those already done for the same config."),
    config_dir: list[str] = typer.Option(
        [],
        "--config-dir",
        help="Your own config directory (e.g. with scenario/"
        "my_map.yaml): its groups and options join the shipped ones for every step; "
        "may be given several times.",
    ),
) -> None:
    """Run a pipeline: its stages in order, skipping those already done for the same resolved config."""
    from pathlib import Path

    from stafpipe.pipeline import run_pipeline

    _exit_with(lambda: run_pipeline(pipeline, force=force, config_dirs=[Path(d) for d in config_dir]))


@app.command(context_settings=_HYDRA_ARGS)
def compare(
    ctx: typer.Context,
    methods: str = typer.Option(
        "", "--methods", help="Comma-separated methods to run (default: every method of the papers and ours)."
    ),
    name: str = typer.Option(
        "", "--name", help="The compare's directory under outputs/pipelines/ (default: compare-SCENARIO)."
    ),
    videos: int = typer.Option(1, "--videos", help="Episodes drawn as video per method (0: none)."),
    force: bool = typer.Option(False, "--force", help="Run every step, even those already done for the same config."),
) -> None:
    """Every method on one scenario in one directory: a table with STAF's Table-1 columns, a trajectory figure and a
    video per method, compare.md listing them; e.g. `stafpipe compare scenario.path=my_map.yaml eval.episodes=10`.
    Trailing arguments are eval overrides for every method."""
    from pathlib import Path

    from stafpipe.compare import parse_methods, run_compare

    _exit_with(lambda: run_compare(list(ctx.args), parse_methods(methods), name, videos, force, Path("outputs")))


@app.command()
def inspect(
    file: str = typer.Argument(..., help="An episode's MCAP file."),
    recover: bool = typer.Option(
        False, "--recover", help="Write FILE.recovered.mcap with every intact chunk's records (a partial episode)."
    ),
) -> None:
    """Summarise an episode's MCAP log and recompute its metrics from the log alone."""
    from stafpipe.episode_log import recover as recover_log
    from stafpipe.inspect_log import describe

    try:
        if recover:
            out = file[: -len(".mcap")] + ".recovered.mcap" if file.endswith(".mcap") else file + ".recovered.mcap"
            kept, channels, damage = recover_log(file, out)
            if not damage:
                typer.echo(f"{file}: no damage found; nothing to recover, nothing written (inspect it as it is)")
                return
            found = "; ".join(map(str, damage))
            typer.echo(f"recovered {kept} messages on {channels} channels into {out} ({found})")
            return
        report, equal = describe(file)
    except StafpipeError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    except OSError as exc:
        _fs_fault_exit(exc)
    typer.echo(report)
    if not equal:
        raise typer.Exit(1)


@app.command()
def export(
    network: str = typer.Argument(
        ...,
        help="staf (the paper's STAF: GNN + low level), staf_planned (the same network under our plan), dgnn (the "
        "DGNN policy) or high (STAF's deep graph cut).",
    ),
    checkpoint: str = typer.Option(
        "", "--checkpoint", help="A policy.pt / high-level checkpoint; empty: the shipped one."
    ),
    output: str = typer.Option("", "--output", help="The ONNX file to write; empty: outputs/export/NETWORK.onnx."),
    ensemble: list[str] = typer.Option(
        None,
        "--ensemble",
        help="Another training run of the policy to average in (repeat it; as method.ensemble); not given: the "
        "shipped partner run with the shipped staf_planned checkpoint, none with any other; --no-ensemble: none.",
    ),
    no_ensemble: bool = typer.Option(False, "--no-ensemble", help="The checkpoint alone, without partner runs."),
) -> None:
    """Write a learned network as ONNX for a robot (inputs, outputs and frames: docs/export.md)."""
    from pathlib import Path

    from stafpipe.export_onnx import export as export_network

    try:
        if no_ensemble and ensemble:
            raise StafpipeError("export: --ensemble and --no-ensemble together")
        members = [] if no_ensemble else (list(ensemble) if ensemble else None)
        path = export_network(network, checkpoint, Path(output or f"outputs/export/{network}.onnx"), members)
    except StafpipeError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    except OSError as exc:
        _fs_fault_exit(exc)
    except ModuleNotFoundError as exc:
        typer.echo(
            f"error: export needs the onnx extra ({exc.name} is missing): pip install 'stafpipe[onnx]'", err=True
        )
        raise typer.Exit(2) from None
    typer.echo(f"wrote {path}")
