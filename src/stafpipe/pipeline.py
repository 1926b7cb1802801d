"""`stafpipe run PIPELINE`: the ordered stage invocations of a pipelines/<name>.yaml file.

A step's run directory is `<out_root>/pipelines/<pipeline>/<NN>-<step>-<hash>`, where the hash is that of the step's
resolved config. A step whose directory already holds a completion marker with the same hash is skipped (unless
forced). An override may name an earlier step's directory as `{steps.<name>.dir}`, and every earlier step's directory
as `{steps.*.dir}` (a comma-separated list, for a report over all of them).

A reference may be a pattern: `{steps.full-*.dir}` is every earlier step whose name matches (fnmatch), in order.

A step may be `{include: <pipeline>}`: that pipeline's steps join this one, named `<pipeline>.<step>`, and keep their
own run directories (`<out_root>/pipelines/<pipeline>/...`), so a study run on its own is not run again by a pipeline
that includes it.

A step may sweep (`over`): a mapping from an axis name to its values, each value a label with the overrides it adds
(a mapping label -> override or list of overrides) or a plain list of labels that add none. The step stands for one
step per combination, the first axis outermost; `{axis}` in its name and overrides is replaced by the label, and the
name must hold every axis so that the steps' names differ. A study's YAML says what varies instead of copying a step
per cell.
"""

from __future__ import annotations

import fnmatch
import itertools
import json
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from stafpipe.config.compose import compose_config
from stafpipe.errors import StafpipeError, yaml_problem
from stafpipe.launch import MARKER, STAGE_FUNCTIONS, config_hash, inputs_hash, launch
from stafpipe.paths import pipelines_dir

STAGES = ("generate", "generate-maps", "train-high", "train-ppo", "eval", "ablate", "plot")
_STEP_REF = re.compile(r"\{steps\.([][A-Za-z0-9_.*?-]+)\.dir\}")
_AXIS = re.compile(r"(?<!\$)\{([A-Za-z_][A-Za-z0-9_]*)\}")  # not a Hydra interpolation ${...}


@dataclass
class PipelineStep:
    """One stage invocation: the stage and its Hydra overrides."""

    name: str
    stage: str
    overrides: list[str]
    home: str = ""
    """The pipeline whose run-directory tree holds this step (set for included steps; empty: the running pipeline)."""
    index: int = -1
    """The step's position in its home pipeline (numbers its run directory)."""


@dataclass
class Pipeline:
    """A named, ordered list of steps, read from YAML."""

    name: str
    description: str
    steps: list[PipelineStep]


def find_pipeline(name_or_path: str) -> Path:
    """A pipeline file given by path, or by name in ./pipelines/ or the shipped pipelines/."""
    candidates = [
        Path(name_or_path),
        Path("pipelines") / f"{name_or_path}.yaml",
        pipelines_dir() / f"{name_or_path}.yaml",
    ]
    for path in candidates:
        if path.is_file():
            return path
    if Path(name_or_path).is_dir():
        raise StafpipeError(f"{name_or_path} is a directory, not a pipeline file (a YAML file with `steps`)")
    shipped = sorted(p.stem for p in pipelines_dir().glob("*.yaml"))
    raise StafpipeError(f"no pipeline '{name_or_path}' (a file, or one of: {', '.join(shipped)})")


def load_pipeline(path: Path, _including: tuple[str, ...] = ()) -> Pipeline:
    """Read and validate a pipeline file, with its includes expanded; errors name the file and the bad field."""
    try:
        raw = OmegaConf.to_container(OmegaConf.load(path))
    except Exception as exc:  # noqa: BLE001 - any parse error becomes one clear message
        raise StafpipeError(f"{path}: not valid YAML ({yaml_problem(exc)})") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("steps"), list) or not raw["steps"]:
        raise StafpipeError(f"{path}: needs a non-empty list 'steps'")
    unknown = set(raw) - {"name", "description", "steps"}
    if unknown:
        raise StafpipeError(f"{path}: unknown field(s) {sorted(unknown)}")
    name_of_pipe = str(raw.get("name", path.stem))
    steps: list[PipelineStep] = []
    for i, item in enumerate(raw["steps"]):
        where = f"{path}: steps[{i}]"
        if isinstance(item, dict) and set(item) == {"include"}:
            steps += _included(str(item["include"]), where, (*_including, name_of_pipe))
            continue
        if not isinstance(item, dict) or set(item) - {"name", "stage", "overrides", "over"}:
            raise StafpipeError(
                f"{where}: a step has 'stage', optional 'name', 'overrides' and 'over' (or is {{include: PIPELINE}}), "
                f"got {item!r}"
            )
        if item.get("stage") not in STAGES:
            raise StafpipeError(f"{where}.stage: must be one of {list(STAGES)}, got {item.get('stage')!r}")
        overrides = item.get("overrides", [])
        if not isinstance(overrides, list) or not all(isinstance(o, str | int | float) for o in overrides):
            raise StafpipeError(f"{where}.overrides: must be a list of strings")
        for name, swept in _swept(str(item.get("name", item["stage"])), [str(o) for o in overrides], item, where):
            if not re.fullmatch(r"[A-Za-z0-9_-]+", name):
                raise StafpipeError(f"{where}.name: '{name}' may hold only letters, digits, '_' and '-'")
            steps.append(PipelineStep(name, item["stage"], swept))
    for i, step in enumerate(steps):
        if any(s.name == step.name for s in steps[:i]):
            raise StafpipeError(f"{path}: step name '{step.name}' is used twice; give the steps distinct names")
    return Pipeline(name_of_pipe, str(raw.get("description", "")), steps)


def _axes(over: Any, where: str) -> dict[str, dict[str, list[str]]]:
    """A step's `over`, checked: axis -> label -> the overrides that label adds."""
    if not isinstance(over, dict) or not over:
        raise StafpipeError(f"{where}.over: must be a mapping from an axis name to its values, got {over!r}")
    axes: dict[str, dict[str, list[str]]] = {}
    for axis, values in over.items():
        key = f"{where}.over.{axis}"
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", str(axis)):
            raise StafpipeError(f"{key}: an axis name is an ASCII identifier")
        if isinstance(values, list) and values and all(isinstance(v, str | int | float) for v in values):
            axes[axis] = {str(v): [] for v in values}
        elif isinstance(values, dict) and values:
            axes[axis] = {}
            for label, adds in values.items():
                adds = [adds] if isinstance(adds, str | int | float) else adds
                if adds is None:
                    adds = []
                if not isinstance(adds, list) or not all(isinstance(o, str | int | float) for o in adds):
                    raise StafpipeError(f"{key}.{label}: must be an override or a list of overrides, got {adds!r}")
                axes[axis][str(label)] = [str(o) for o in adds]
        else:
            raise StafpipeError(f"{key}: must be a non-empty list of labels or mapping label -> overrides")
        if len(axes[axis]) != len(values):
            raise StafpipeError(f"{key}: labels must differ")
    return axes


def _swept(name: str, overrides: list[str], item: dict, where: str) -> list[tuple[str, list[str]]]:
    """(name, overrides) of each step a pipeline step stands for: itself, or one per combination of its `over`."""
    if "over" not in item:
        return [(name, overrides)]
    axes = _axes(item["over"], where)
    missing = [a for a in axes if "{" + a + "}" not in name]
    if missing:
        raise StafpipeError(f"{where}.name: '{name}' must hold {{{missing[0]}}} so that each swept step has its own")
    out = []
    for combo in itertools.product(*(labels.items() for labels in axes.values())):
        labels = {axis: label for axis, (label, _) in zip(axes, combo, strict=True)}

        def fill(text: str, _labels: dict[str, str] = labels) -> str:
            return _AXIS.sub(lambda m: _labels.get(m.group(1), m.group(0)), text)

        added = [o for _, adds in combo for o in adds]
        out.append((fill(name), [fill(o) for o in [*overrides, *added]]))
    return out


def _included(name: str, where: str, including: tuple[str, ...]) -> list[PipelineStep]:
    """The steps of pipeline `name`, renamed `<name>.<step>` (their references too), each keeping its own pipeline's
    run-directory tree and number."""
    if name in including:
        raise StafpipeError(f"{where}.include: '{name}' includes itself ({' -> '.join([*including, name])})")
    inner = load_pipeline(find_pipeline(name), including)
    prefix = inner.name + "."

    def rename(match: re.Match[str]) -> str:
        return "{steps." + prefix + match.group(1) + ".dir}"

    out = []
    for i, step in enumerate(inner.steps):
        if step.home:  # included two levels down: already named and housed
            out.append(PipelineStep(prefix + step.name, step.stage, step.overrides, step.home, step.index))
            continue
        overrides = [_STEP_REF.sub(rename, o) for o in step.overrides]
        out.append(PipelineStep(prefix + step.name, step.stage, overrides, inner.name, i))
    return out


def _is_done(run_dir: Path, digest: str, inputs: str | None = None) -> bool:
    """Whether `run_dir` finished with config hash `digest` (and, if given, the same `launch.inputs_hash`)."""
    marker = run_dir / MARKER
    try:
        done = json.loads(marker.read_text())
    except (OSError, ValueError):
        return False
    return done.get("config_hash") == digest and (inputs is None or done.get("inputs_hash") == inputs)


def search_path_override(config_dirs: list[Path]) -> str:
    """The override that adds a user's config directories to Hydra's search path (their groups and options join the
    shipped ones; an option of the same name wins over the shipped one)."""
    for d in config_dirs:
        if not d.is_dir():
            raise StafpipeError(f"--config-dir {d}: not a directory")
    entries = ", ".join("'file://" + str(d.resolve()).replace("'", "\\'") + "'" for d in config_dirs)
    return f"hydra.searchpath=[{entries}]"


def run_pipeline(
    name_or_path: str, force: bool = False, out_root: Path = Path("outputs"), config_dirs: list[Path] | None = None
) -> int:
    """Run every step in order; stop at the first failure. Returns the exit code. `config_dirs`: the user's own
    config directories, searched by every step (`stafpipe run --config-dir`)."""
    pipe = load_pipeline(find_pipeline(name_or_path))
    extra = [search_path_override(config_dirs)] if config_dirs else []
    plan = plan_pipeline(pipe, out_root, extra)
    for i, planned in enumerate(plan, start=1):
        head = f"[{i}/{len(plan)}] {planned[0].name} ({planned[0].stage})"
        code = run_step(head, planned, force)
        if code != 0:
            print(f"{head}: failed (exit code {code}); pipeline {pipe.name} stopped")
            return code
    print(f"pipeline {pipe.name}: all {len(plan)} steps done")
    return 0


def run_step(head: str, planned: tuple[PipelineStep, list[str], Path, str, DictConfig], force: bool) -> int:
    """Run one planned step (`plan_pipeline`) into its run directory, or skip it if it is already done for the same
    config and inputs; its exit code (0 for a skip, non-zero where the step did not finish)."""
    step, overrides, run_dir, digest, cfg = planned
    if not force and _is_done(run_dir, digest, inputs_hash(cfg)):  # inputs: once the steps before are done
        print(f"{head}: skipped, already done for this config in {run_dir}")
        return 0
    started = time.perf_counter()
    code = launch(step.stage, [*overrides, f"hydra.run.dir='{run_dir}'"])
    if code != 0 or not _is_done(run_dir, digest):
        return code or 1
    print(f"{head}: done in {time.perf_counter() - started:.1f} s -> {run_dir}")
    return 0


def plan_pipeline(
    pipe: Pipeline, out_root: Path, extra: list[str]
) -> list[tuple[PipelineStep, list[str], Path, str, DictConfig]]:
    """Every step composed (a bad config stops the pipeline before any work): the step, its overrides with earlier
    steps' directories filled in, its run directory, its config hash and its config."""
    dirs: dict[str, Path] = {}
    stages: dict[str, str] = {}
    plan: list[tuple[PipelineStep, list[str], Path, str, DictConfig]] = []
    for i, step in enumerate(pipe.steps):
        if step.stage not in STAGE_FUNCTIONS:
            raise StafpipeError(
                f"pipeline {pipe.name}: step '{step.name}': unknown stage {step.stage!r}; stages: "
                f"{sorted(STAGE_FUNCTIONS)}"
            )

        def ref(match: re.Match[str], _step: PipelineStep = step) -> str:
            names = [n for n in dirs if fnmatch.fnmatchcase(n, match.group(1))]
            if not names:
                raise StafpipeError(f"step '{_step.name}' refers to '{match.group(1)}', which is not an earlier step")
            kinds = {stages[n] for n in names}
            if len(kinds) > 1 and match.group(1) != "*":  # a pattern meant for one kind of step that caught another
                raise StafpipeError(
                    f"step '{_step.name}': '{match.group(1)}' matches steps of stages {sorted(kinds)}; "
                    "narrow the pattern so that it names steps of one stage"
                )
            return ",".join(str(dirs[n]) for n in names)

        overrides = [*extra, *(_STEP_REF.sub(ref, o) for o in step.overrides)]
        try:
            cfg = compose_config(step.stage, overrides)
        except Exception as exc:  # noqa: BLE001 - Hydra's composition errors, said in the user's terms
            from stafpipe.config.compose_errors import explain

            raise StafpipeError(
                f"pipeline {pipe.name}: step '{step.name}' has a bad config: {explain(exc, step.stage, overrides)}"
            ) from None
        digest = config_hash(cfg)
        home, number, short = (
            (step.home, step.index, step.name.rsplit(".", 1)[-1]) if step.home else (pipe.name, i, step.name)
        )
        run_dir = (out_root / "pipelines" / home / f"{number:02d}-{short}-{digest[:10]}").resolve()
        dirs[step.name] = run_dir
        stages[step.name] = step.stage
        plan.append((step, overrides, run_dir, digest, cfg))
    return plan
