"""`stafpipe compare [OVERRIDES]`: every method on one scenario, side by side in one directory: each method's eval run,
STAF's Table-1 columns for all of them in one table, a trajectory figure and an MP4 video per method (a GIF takes
several times as long to encode: `stafpipe plot video` on a method's eval run makes one), and `compare.md`
that lists them. Built as a pipeline run (`pipeline.plan_pipeline`, `pipeline.run_step`), so a step already done for
the same config and inputs is skipped and a killed compare resumes where it stopped. A method that refuses the
scenario or fails is said so in the table, with its error, and the others go on."""

from __future__ import annotations

import contextlib
import io
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from stafpipe.errors import StafpipeError
from stafpipe.interrupt import INTERRUPTED
from stafpipe.io import atomic_write
from stafpipe.pipeline import Pipeline, PipelineStep, plan_pipeline, run_step
from stafpipe.registry import load_plugins

COMPARE_METHODS = ("staf", "staf_planned", "dgnn", "lf", "zhu", "cezayirli")
"""Every method of the three papers and ours; `straight` (a test fixture) only when asked for."""


@dataclass
class Outcome:
    method: str
    run_dir: Path
    code: int
    error: str = ""


class _Tee(io.TextIOBase):
    """Writes through to the real stream and keeps a copy, so that a method's error is shown and also recorded."""

    def __init__(self, stream: io.TextIOBase) -> None:
        self.stream, self.kept = stream, io.StringIO()

    def write(self, text: str) -> int:
        self.kept.write(text)
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()


def _error_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip().startswith("error:")]
    return lines[-1].removeprefix("error:").strip() if lines else ""


def parse_methods(text: str) -> list[str]:
    """`--methods a,b`: known methods, in the order given, each once (empty: `COMPARE_METHODS`); a clear error
    naming an unknown one."""
    if not text.strip():
        return list(COMPARE_METHODS)
    methods = [m.strip() for m in text.split(",") if m.strip()]
    unknown = [m for m in methods if m not in load_plugins()]
    if not methods or unknown:
        raise StafpipeError(f"--methods: unknown method(s) {unknown or [text]}; methods: {sorted(load_plugins())}")
    return list(dict.fromkeys(methods))


def _plot_steps(ran: list[Outcome], videos: int) -> list[PipelineStep]:
    dirs = ",".join(f"{{steps.eval-{o.method}.dir}}" for o in ran)
    steps = [PipelineStep("table", "plot", ["plot.kind=table", f"plot.run_dirs=[{dirs}]"])]
    for o in ran:
        ref = f"plot.run_dir={{steps.eval-{o.method}.dir}}"
        steps.append(
            PipelineStep(f"trajectories-{o.method}", "plot", ["plot.kind=trajectories", ref, "plot.max_episodes=1"])
        )
        if videos:
            steps.append(
                PipelineStep(
                    f"video-{o.method}",
                    "plot",
                    ["plot.kind=video", ref, f"plot.max_episodes={videos}", "plot.video_formats=[mp4]"],
                )
            )
    return steps


def _index(name: str, outcomes: list[Outcome], plotted: dict[str, Path], overrides: list[str]) -> str:
    lines = [
        f"# Compare: {name}",
        "",
        f"`stafpipe compare --methods {','.join(o.method for o in outcomes)} {' '.join(overrides)}`: each method's "
        "eval run, trajectory figure and video directories, beside this file.",
        "",
        "| method | status | eval run | trajectories | video |",
        "|---|---|---|---|---|",
    ]
    for o in outcomes:
        status = "ran" if o.code == 0 else f"cannot run it (exit code {o.code}): {o.error or 'see its log'}"
        traj, video = plotted.get(f"trajectories-{o.method}"), plotted.get(f"video-{o.method}")
        cell = lambda d: f"`{d.name}/`" if d is not None and d.is_dir() else "-"  # noqa: E731
        lines.append(f"| {o.method} | {status} | {cell(o.run_dir)} | {cell(traj)} | {cell(video)} |")
    table = plotted.get("table")
    if table is not None and (table / "table.md").is_file():
        lines += ["", (table / "table.md").read_text()]
    return "\n".join(lines) + "\n"


def run_compare(
    overrides: list[str],
    methods: list[str],
    name: str = "",
    videos: int = 1,
    force: bool = False,
    out_root: Path = Path("outputs"),
) -> int:
    """Run every method of `methods` on the scenario the eval `overrides` give, then the table, figures and videos of
    those that ran; write `compare.md` into the compare's directory. Exit code 0 when at least one method ran, 2 when
    every method refused the input, else 1."""
    if name and not re.fullmatch(r"[A-Za-z0-9_-]+", name):
        raise StafpipeError(f"--name: '{name}' may hold only letters, digits, '_' and '-' (a directory name)")
    if videos < 0:
        raise StafpipeError(f"--videos: must be >= 0 (episodes drawn as video per method), got {videos}")
    evals = [PipelineStep(f"eval-{m}", "eval", [f"method={m}", *overrides, "eval.log_episodes=true"]) for m in methods]
    probe = plan_pipeline(Pipeline("compare", "", evals[:1]), out_root, [])  # the scenario's name, bad input refused
    node = probe[0][4].scenario
    scenario = Path(str(node.path)).stem if node.get("path") else str(node.get("name") or "scenario")
    name = name or "compare-" + re.sub(r"[^A-Za-z0-9_-]", "_", scenario)  # a directory name Hydra's overrides can carry
    plan = plan_pipeline(Pipeline(name, "", evals), out_root, [])  # every method's config before any work
    home = plan[0][2].parent
    outcomes = []
    for i, planned in enumerate(plan, start=1):
        head = f"[{i}/{len(plan)}] {planned[0].name} ({planned[0].stage})"
        tee = _Tee(sys.stderr)  # type: ignore[arg-type]
        with contextlib.redirect_stderr(tee):
            code = run_step(head, planned, force)
        if code == INTERRUPTED:
            return code
        outcome = Outcome(planned[0].name.removeprefix("eval-"), planned[2], code, _error_line(tee.kept.getvalue()))
        if code != 0:
            print(f"{head}: cannot run it (exit code {code}); going on with the others")
        outcomes.append(outcome)
    ran = [o for o in outcomes if o.code == 0]
    if not ran:  # nothing to compare: no index either; refused by every method (exit 2) is the user's input
        with contextlib.suppress(OSError):
            home.rmdir()  # only if empty: steps done earlier for other settings stay
        print(f"compare {name}: no method ran", file=sys.stderr)
        return 2 if all(o.code == 2 for o in outcomes) else 1
    plotted: dict[str, Path] = {}
    steps = _plot_steps(ran, videos)
    full = plan_pipeline(Pipeline(name, "", [*evals, *steps]), out_root, [])[len(evals) :]
    for i, planned in enumerate(full, start=1):
        code = run_step(f"[{i}/{len(full)}] {planned[0].name} (plot)", planned, force)
        if code != 0:
            print(f"compare {name}: step {planned[0].name} failed (exit code {code}); stopped")
            return code
        plotted[planned[0].name] = planned[2]
    index = atomic_write(home / "compare.md", lambda tmp: tmp.write_text(_index(name, outcomes, plotted, overrides)))
    print(f"compare {name}: {len(ran)} of {len(outcomes)} methods ran -> {index}")
    return 0
