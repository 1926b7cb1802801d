"""Runs a stage through `hydra.main`, so that multirun, launchers, `--cfg` and `--info` work as in plain Hydra.

Every stage is a plain function `run_<stage>(cfg, out_dir) -> list[Path]` (its result files). `stage_task` is the one
Hydra task function: it calls the stage, then writes the resolved config and a completion marker (`stage.json`) that
pipelines use to skip finished work.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import importlib
import json
import logging
import os
import re
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import hydra
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from stafpipe import __version__
from stafpipe.config import register_configs
from stafpipe.config.checks import check_run_config
from stafpipe.config.compose import compose_config, config_name
from stafpipe.errors import StafpipeError
from stafpipe.interrupt import INTERRUPTED, stop_at_boundaries
from stafpipe.io import OBJECTIVE, atomic_write, write_json
from stafpipe.paths import conf_dir
from stafpipe.run_lock import RunDirLock

log = logging.getLogger(__name__)

# Stage name (as typed on the command line) -> "module:function" (a test checks it matches the CLI).
STAGE_FUNCTIONS: dict[str, str] = {
    "generate": "stafpipe.stages.generate:run_generate",
    "generate-maps": "stafpipe.stages.generate_maps:run_generate_maps",
    "eval": "stafpipe.stages.eval:run_eval",
    "plot": "stafpipe.stages.plot:run_plot",
    "train-high": "stafpipe.stages.train_high:run_train_high",
    "ablate": "stafpipe.stages.ablate:run_ablate",
    "train-ppo": "stafpipe.stages.train_ppo:run_train_ppo",
}
MARKER = "stage.json"


def config_hash(cfg: DictConfig) -> str:
    """SHA-256 of the resolved job config: equal configs give equal hashes, whatever their origin."""
    text = OmegaConf.to_yaml(cfg, resolve=True, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


# The config sections whose empty `*checkpoint` keys a stage loads a shipped checkpoint for (inputs_hash).
SHIPPED_READERS: dict[str, tuple[str, ...]] = {"eval": ("method",), "train-ppo": ("train_ppo",), "ablate": ("high",)}


def inputs_hash(cfg: DictConfig) -> str:
    """SHA-256 of what a run reads besides its config: every file or directory a config string names (a file's
    content; a directory's file names, sizes and modification times) and, where a `*checkpoint` key the stage reads
    is empty, the shipped checkpoints it falls back to. A pipeline reruns a step whose inputs changed under the same
    config (a retrained shipped policy, an edited map), which the config hash alone cannot see."""
    from stafpipe.paths import package_dir

    digest = hashlib.sha256()
    readers = SHIPPED_READERS.get(str(cfg.get("stage", "")), ())
    shipped = False

    def visit(node: object, key: str) -> None:
        nonlocal shipped
        if isinstance(node, dict):
            for k, v in sorted(node.items()):
                visit(v, f"{key}.{k}" if key else str(k))
        elif isinstance(node, list):
            for v in node:
                visit(v, key)
        elif key.endswith("checkpoint") and node in ("", None):
            shipped = shipped or key.split(".")[0] in readers
        elif isinstance(node, str) and node and len(node) < 4096 and Path(node).exists():
            digest.update(f"{key}={node}".encode())
            _digest_path(Path(node), digest)

    visit(OmegaConf.to_container(cfg, resolve=True), "")
    if shipped:
        _digest_path(package_dir() / "checkpoints", digest)
    return digest.hexdigest()


def _digest_path(path: Path, digest: hashlib._Hash) -> None:
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        stat = f.stat()
        if path.is_dir():
            digest.update(f"{f.relative_to(path)}:{stat.st_size}:{stat.st_mtime_ns}".encode())
        else:
            digest.update(f.read_bytes())


def stage_function(stage: str) -> Callable[[DictConfig, Path], list[Path]]:
    """Import the plain function behind `stage`."""
    module, _, name = STAGE_FUNCTIONS[stage].partition(":")
    return getattr(importlib.import_module(module), name)


def _detach_file_logs(out_dir: Path) -> None:
    """Close and remove the log file handlers Hydra attached for a run in `out_dir`: a later log call in the same
    process would otherwise reopen a file in a deleted directory."""
    for logger in [logging.getLogger(), *logging.Logger.manager.loggerDict.values()]:
        if not isinstance(logger, logging.Logger):
            continue
        for handler in list(logger.handlers):
            if isinstance(handler, logging.FileHandler) and Path(handler.baseFilename).is_relative_to(
                out_dir.resolve()
            ):
                logger.removeHandler(handler)
                handler.close()


FS_FAULTS = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
}
"""File-system faults reported in one line (the path and the cause) instead of a traceback."""
UNFINISHED = "the run did not finish (no stage.json); its unfinished files were removed"


def fs_fault(exc: BaseException | None, where: Path | None = None) -> str | None:
    """One line for a file-system fault anywhere in `exc`'s chain (disk full, read-only, no permission), or None."""
    while exc is not None:
        if isinstance(exc, OSError) and exc.errno in FS_FAULTS:
            path = exc.filename or (f"writing into {where}" if where else "writing the run's outputs")
            return f"{path}: {FS_FAULTS[exc.errno]}"
        exc = exc.__cause__ or exc.__context__
    return None


def _remove_partials(out_dir: Path) -> None:
    """Files a failed run was still writing: episode logs (`*.part`) and atomic writes' temporaries (`.*.tmp-*`)."""
    if out_dir.is_dir():
        for p in [*out_dir.glob("episodes/*.part"), *out_dir.rglob(".*.tmp-*")]:
            with contextlib.suppress(OSError):
                p.unlink()


def _only_hydra_files(out_dir: Path) -> bool:
    """Nothing but Hydra's own files (`.hydra/`, logs) and empty folders."""
    for p in out_dir.iterdir():
        if p.name == ".hydra" or p.suffix == ".log":
            continue
        if not p.is_dir() or any(q.is_file() for q in p.rglob("*")):
            return False
    return True


def _discard_if_empty(out_dir: Path) -> None:
    # A run that failed before writing any result leaves no directory behind: only Hydra's own files are in it.
    if out_dir.is_dir() and _only_hydra_files(out_dir):
        _detach_file_logs(out_dir)
        shutil.rmtree(out_dir, ignore_errors=True)
        if re.fullmatch(r"\d{4}-\d{2}-\d{2}", out_dir.parent.name):  # Hydra's date folder, if this run was alone
            with contextlib.suppress(OSError):  # in it; never a folder the user named (it may be their cwd)
                out_dir.parent.rmdir()


RESUMABLE = frozenset({"train-ppo", "train-high"})
"""Stages whose run directory holds a training state a rerun goes on from (`resume=true`): kept when interrupted."""


def _clear_outputs(out_dir: Path) -> bool:
    """Remove what an earlier or interrupted run of a stage left in `out_dir` that a rerun could mix with its own: its
    completion marker, its episode logs (`episodes/*.mcap`) and its per-episode figures (`*episode_NNNN.*`), so that
    `plot trajectories` can never draw a stale episode. Only files of those names: a directory the user named for
    the run may hold files of theirs. True if anything was removed."""
    if not out_dir.is_dir():
        return False
    stale = [out_dir / MARKER] if (out_dir / MARKER).is_file() else []
    stale += [*out_dir.glob("episodes/*.mcap"), *out_dir.glob("episodes/*.part")]
    stale += [p for p in out_dir.glob("*episode_[0-9][0-9][0-9][0-9].*") if p.is_file()]
    for p in stale:
        with contextlib.suppress(OSError):
            p.unlink()
    with contextlib.suppress(OSError):
        (out_dir / "episodes").rmdir()  # only if empty
    return bool(stale)


def _abandon(out_dir: Path, lock: RunDirLock, clear: bool = False) -> None:
    """A run that stops unfinished: its unfinished files removed (and with `clear` its episode logs and marker), its
    lock released, its directory removed if nothing else is in it. Only a run holding the lock touches the directory:
    another run's is never touched."""
    if not lock.held:
        return
    _remove_partials(out_dir)
    if clear:
        _clear_outputs(out_dir)
    with contextlib.suppress(OSError):
        lock.release()
    _discard_if_empty(out_dir)


def stage_task(cfg: DictConfig) -> float | None:
    """Hydra's task function for every stage; returns the run's objective (`objective`) where its stage has one."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    started = time.perf_counter()
    lock = RunDirLock(out_dir)
    resumable = str(cfg.get("stage")) in RESUMABLE
    try:
        lock.acquire()  # refused: the directory is another run's, so nothing in it is touched
        check_run_config(cfg, HydraConfig.get().overrides.task)
        _remove_partials(out_dir)  # a killed run's unfinished files are never valid, resumable stage or not
        if not resumable and _clear_outputs(out_dir):
            log.warning("%s held files of an earlier run of this stage; removed, the run starts over", out_dir)
        inputs = inputs_hash(cfg)  # before the stage: what it read, not what it wrote
        with stop_at_boundaries():  # Ctrl-C and SIGTERM end the stage at its next step or item (interrupt.py)
            outputs = stage_function(cfg.stage)(cfg, out_dir)
    except KeyboardInterrupt:
        _abandon(out_dir, lock, clear=not resumable)
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            raise
        kept = "its training state is kept: the same command with resume=true goes on from it"
        gone = "its episode logs were removed and it wrote no results; the same command starts it over"
        print(f"interrupted: {cfg.stage} in {out_dir}; {kept if resumable else gone}", file=sys.stderr)
        sys.exit(INTERRUPTED)
    except StafpipeError as exc:
        if lock.held:
            lock.release()
            _discard_if_empty(out_dir)
        if HydraConfig.get().mode == RunMode.MULTIRUN:
            raise  # the launcher reports it for this job of the sweep
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    except BaseException as exc:
        _abandon(out_dir, lock)
        fault = fs_fault(exc, out_dir)
        if fault is None or HydraConfig.get().mode == RunMode.MULTIRUN:
            raise
        print(f"error: {fault}; {UNFINISHED}", file=sys.stderr)
        sys.exit(2)
    try:
        _finish(cfg, out_dir, outputs, inputs, started)
    except OSError as exc:
        _remove_partials(out_dir)
        fault = fs_fault(exc, out_dir)
        if fault is None:
            raise
        print(f"error: {fault}; {UNFINISHED}", file=sys.stderr)
        sys.exit(2)
    finally:
        with contextlib.suppress(OSError):
            lock.release()
    return objective(out_dir)


def objective(out_dir: Path) -> float | None:
    """The value of a finished run's `objective.json`, or None where its stage writes none."""
    path = out_dir / OBJECTIVE
    if not path.is_file():
        return None
    return float(json.loads(path.read_text())["value"])


def _finish(cfg: DictConfig, out_dir: Path, outputs: list[Path], inputs: str, started: float) -> None:
    """The resolved config, then the completion marker (last: its presence means the run is complete)."""
    resolved = OmegaConf.to_yaml(cfg, resolve=True)
    atomic_write(out_dir / "config.yaml", lambda tmp: tmp.write_text(resolved))
    write_json(
        out_dir / MARKER,
        {
            "stage": cfg.stage,
            "config_hash": config_hash(cfg),
            "inputs_hash": inputs,
            "outputs": sorted(str(Path(p).relative_to(out_dir)) for p in outputs),
            "seconds": round(time.perf_counter() - started, 3),
            "stafpipe_version": __version__,
        },
    )
    log.info("%s finished: %s", cfg.stage, out_dir)


def _config_problem(stage: str, overrides: Sequence[str]) -> str | None:
    """What is wrong with the configs of a sweep, in the user's terms, or None: every value of every swept key is
    composed before the first job runs, so a bad value late in a sweep does not stop it half done."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from stafpipe.config.compose_errors import explain, jobs_to_check

    try:
        for job in jobs_to_check(overrides) or []:
            check_run_config(compose_config(stage, job), job)
    except (HydraException, OmegaConfBaseException) as exc:
        return explain(exc, stage, list(overrides))
    except StafpipeError as exc:
        return str(exc)
    finally:
        GlobalHydra.instance().clear()
    return None


def _maps_of(override: str) -> str:
    """In a sweep, `scenario.path=DIR` (a directory) stands for every scenario file in it: one job per `*.yaml`, in
    name order, for Hydra's launcher to spread (`hydra/launcher=local`: one process per core). Other overrides, and
    a path that is not a directory, are left as they are."""
    key, sep, value = override.partition("=")
    if not sep or key.lstrip("+") != "scenario.path":
        return override
    folder = Path(value.strip().strip("'\""))
    if not value.strip() or not folder.is_dir():
        return override
    files = sorted(folder.glob("*.yaml"))
    if not files:
        return override  # the scenario loader says it is a directory without a scenario in it
    quoted = ",".join("'" + str(f).replace("\\", "\\\\").replace("'", "\\'") + "'" for f in files)
    return f"{key}={quoted}"


def launch(stage: str, overrides: Sequence[str]) -> int:
    """Run `stage` with Hydra command-line `overrides` (and flags such as -m, --cfg); return the exit code."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from stafpipe.config.compose_errors import explain

    try:
        register_configs()  # imports the method plugins: a broken one is a bad input, named
    except StafpipeError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    logging.raiseExceptions = False  # a log file on a full disk must not print tracebacks over the one-line error
    if any(o in ("-m", "--multirun") for o in overrides):
        problem = _config_problem(stage, overrides)  # every value of the sweep, before its first job runs
        if problem:
            print(f"error: {problem}", file=sys.stderr)
            return 2
        # after the check: the maps of a directory differ only in the path, which composing each would not check
        overrides = [_maps_of(o) for o in overrides]
    saved_argv, saved_full_error = sys.argv, os.environ.get("HYDRA_FULL_ERROR")
    sys.argv = [f"stafpipe {stage}", *overrides]
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra raises its errors to us instead of printing them and exiting 1
    GlobalHydra.instance().clear()
    main = hydra.main(version_base="1.3", config_path=str(conf_dir()), config_name=config_name(stage))(stage_task)
    try:
        main()
    except SystemExit as exc:
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    except (HydraException, OmegaConfBaseException) as exc:  # a config that does not compose: the user's error
        print(f"error: {explain(exc, stage, list(overrides))}", file=sys.stderr)
        return 2
    except StafpipeError as exc:  # a job of a sweep (stage_task re-raises in multirun mode)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # Hydra could not make the run directory (read-only, full), or a sweep job's fault
        fault = fs_fault(exc)
        if fault is None:
            raise
        print(f"error: {fault}", file=sys.stderr)
        return 2
    finally:
        sys.argv = saved_argv
        if saved_full_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = saved_full_error
        GlobalHydra.instance().clear()
    return 0
