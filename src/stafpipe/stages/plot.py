"""`stafpipe plot KIND RUN_DIR`: figures drawn from a finished run directory, written as PNG and PDF into the plot run's
own directory (which, like every run directory, carries its resolved config)."""

from __future__ import annotations

import logging
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pandas as pd
from matplotlib.figure import Figure
from omegaconf import DictConfig, OmegaConf

from stafpipe.config.schema import PlotConfig
from stafpipe.errors import StafpipeError
from stafpipe.io import atomic_write, save_figure, write_table
from stafpipe.sections import section

log = logging.getLogger(__name__)


def _episode_logs(pc: PlotConfig, run_dir: Path) -> list[Path]:
    """The episode logs an eval run's figures are drawn from: the first `plot.max_episodes` (0: all), in episode
    order; a clear error where the run holds none."""
    from stafpipe.plots.trajectories import episode_files

    files = episode_files(run_dir)
    if not files:
        raise StafpipeError(
            f"plot.run_dir: {run_dir} holds no episodes/*.mcap (is it an eval run with eval.log_episodes?)"
        )
    return files[: pc.max_episodes] if pc.max_episodes else files


def _trajectory_figures(pc: PlotConfig, run_dir: Path) -> dict[str, Figure]:
    from stafpipe.episode_log import read_episode
    from stafpipe.plots.trajectories import trajectory_figure

    files = _episode_logs(pc, run_dir)
    records = [read_episode(f) for f in files]  # all read (and validated) before anything is written
    return {f"trajectories_{path.stem}": trajectory_figure(rec) for path, rec in zip(files, records, strict=True)}


def _connectivity_figures(pc: PlotConfig, run_dir: Path) -> dict[str, Figure]:
    from stafpipe.episode_log import read_episode
    from stafpipe.plots.trajectories import connectivity_figure

    files = _episode_logs(pc, run_dir)
    return {"connectivity": connectivity_figure([read_episode(f) for f in files])}


def _region_figures(pc: PlotConfig, run_dir: Path) -> dict[str, Figure]:
    from stafpipe.episode_log import read_episode
    from stafpipe.plots.zhu import regions_figure, snapshot_times

    files = _episode_logs(pc, run_dir)
    records = [read_episode(f) for f in files]
    return {
        f"regions_{path.stem}": regions_figure(rec, list(pc.times) or snapshot_times(rec))
        for path, rec in zip(files, records, strict=True)
    }


def _timing_tables(run_dir: Path) -> dict[str, str]:
    """Zhu's Table I from an eval run's results table, as Markdown and LaTeX."""
    from stafpipe.plots.zhu import latex_table, markdown_timing, timing_table

    path = run_dir / "results.parquet"
    if not path.is_file():
        raise StafpipeError(f"plot.run_dir: {run_dir} holds no results.parquet (is it an eval run?)")
    try:
        results = pd.read_parquet(path)
    except Exception as exc:  # noqa: BLE001 (pyarrow raises several kinds for a damaged file)
        raise StafpipeError(f"plot.run_dir: {path} is not a readable table ({type(exc).__name__})") from None
    table = timing_table(results)
    scen = ", ".join(sorted(set(results["scenario"].astype(str)))) if "scenario" in results else "?"
    n = ", ".join(str(v) for v in sorted(set(results["n"].tolist()))) if "n" in results else "?"
    caption = f"Computation time [ms] per cycle, whole team ({scen}, {n} robots, {len(results)} episodes)"
    return {"timing.md": f"{caption}\n\n{markdown_timing(table)}", "timing.tex": latex_table(table, caption)}


def _floats(x: Any) -> Any:
    """A config container with every number a float: 15 and 15.0 are the same wall."""
    if isinstance(x, dict):
        return {k: _floats(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_floats(v) for v in x]
    return float(x) if isinstance(x, int | float) and not isinstance(x, bool) else x


def _is_papers_corridor(run_dir: Path) -> bool:
    """Whether an eval run is on STAF's Table-1 map: the shipped corridor's world and walls, unchanged by overrides."""
    from stafpipe.paths import conf_dir

    if not (run_dir / "config.yaml").is_file():
        return False
    loaded = OmegaConf.to_container(OmegaConf.load(run_dir / "config.yaml"))
    run = (loaded.get("scenario") if isinstance(loaded, dict) else None) or {}
    shipped = OmegaConf.to_container(OmegaConf.load(conf_dir() / "scenario" / "corridor.yaml"))
    if not isinstance(shipped, dict):
        return False
    return all(_floats(run.get(k)) == _floats(shipped.get(k)) for k in ("world", "obstacles"))


def eval_runs(run_dir: Path) -> list[Path]:
    """The eval runs a directory stands for: itself if it holds results.parquet, else the job directories of a
    multirun (`stafpipe eval -m ...`: numbered subdirectories, in job order). A clear error where it is neither."""
    if (run_dir / "results.parquet").is_file():
        return [run_dir]
    jobs = sorted((d for d in run_dir.glob("*") if d.name.isdigit() and d.is_dir()), key=lambda d: int(d.name))
    if jobs and (run_dir / "multirun.yaml").is_file():
        missing = [j.name for j in jobs if not (j / "results.parquet").is_file()]
        if missing:
            raise StafpipeError(
                f"plot.run_dirs: {run_dir} is a multirun whose jobs {missing} hold no results.parquet "
                "(did they fail, or is it not an eval sweep?)"
            )
        return jobs
    raise StafpipeError(f"plot.run_dirs: {run_dir} holds no results.parquet (is it an eval run or an eval multirun?)")


def _staf_tables(pc: PlotConfig) -> dict[str, str]:
    """STAF Table 1 (and Table 2 where teams split) from the results of eval runs, ours beside the paper's."""
    from stafpipe.plots.staf_tables import markdown, subteam_tables, summary_table

    frames = []
    given = [pc.run_dir, *pc.run_dirs] if pc.run_dir else list(pc.run_dirs)
    for run, d in enumerate(d for g in given for d in eval_runs(Path(g))):
        path = d / "results.parquet"
        try:
            frames.append(pd.read_parquet(path).assign(run=run, paper_cell=_is_papers_corridor(Path(d))))
        except Exception as exc:  # noqa: BLE001 (pyarrow raises several kinds for a damaged file)
            raise StafpipeError(f"plot.run_dirs: {path} is not a readable table ({type(exc).__name__})") from None
    results = pd.concat(frames, ignore_index=True)
    table = summary_table(results)
    text = markdown(table, "Table 1: team")
    subs = subteam_tables(results)
    if len(subs):
        text += "\n" + markdown(subs, "Table 2: subteams (STAF-sub#: SR, TT and CFI of each subteam)", paper=False)
    out = {"table.md": text, "table.csv": table.to_csv(index=False)}
    if len(subs):
        out["table2.csv"] = subs.to_csv(index=False)
    print(text)
    return out


def _partition_figures(pc: PlotConfig, run_dir: Path) -> dict[str, Figure]:
    """The partitions of an ablate run (and its ARI curve for the noise study), from its tables."""
    from stafpipe.plots.partitions import ari_figure, partition_figure

    parts_path, summary_path = run_dir / "partitions.parquet", run_dir / "summary.parquet"
    if not parts_path.is_file():
        raise StafpipeError(f"plot.run_dir: {run_dir} holds no partitions.parquet (is it an ablate run?)")
    try:
        parts = pd.read_parquet(parts_path)
        summary = pd.read_parquet(summary_path) if summary_path.is_file() else None
    except Exception as exc:  # noqa: BLE001 (pyarrow raises several kinds for a damaged file)
        raise StafpipeError(f"plot.run_dir: unreadable table in {run_dir} ({type(exc).__name__}: {exc})") from None
    missing = {"panel", "robot", "x", "y", "goal_x", "goal_y", "subteam"} - set(parts.columns)
    if missing:
        raise StafpipeError(f"plot.run_dir: {parts_path} lacks columns {sorted(missing)}")
    figures = {"partitions": partition_figure(parts)}
    if summary is not None and {"sigma", "ari", "ari_ci95"} <= set(summary.columns):
        figures["ari_vs_noise"] = ari_figure(summary)
    return figures


def _adaptation_figures(pc: PlotConfig, run_dir: Path, out_dir: Path) -> dict[str, Figure]:
    """Each episode's subteam scale and type integrity over time (adaptation.py), and their samples as
    adaptation_<episode>.csv, all episodes read before anything is written."""
    from stafpipe.adaptation import adaptation_series
    from stafpipe.episode_log import read_episode
    from stafpipe.metrics import MetricContext
    from stafpipe.plots.adaptation import adaptation_figure

    files = _episode_logs(pc, run_dir)
    series = {}
    for path in files:
        rec = read_episode(path)
        ctx = MetricContext(**rec.context)
        series[path.stem] = (rec, adaptation_series(rec.time, rec.positions, rec.velocities, rec.subteams, ctx))
    for stem, (_, frame) in series.items():
        write_table(frame, out_dir / f"adaptation_{stem}")
    return {
        f"adaptation_{stem}": adaptation_figure(frame, f"{rec.method}, {stem}") for stem, (rec, frame) in series.items()
    }


def _training_figures(pc: PlotConfig, run_dir: Path) -> dict[str, Figure]:
    """Learning curves of a train-ppo run (learning_curves.parquet) or loss curves of a train-high run
    (losses.parquet)."""
    from stafpipe.plots.training import loss_curve_figure, ppo_figure

    for name, draw in (("learning_curves", ppo_figure), ("losses", loss_curve_figure)):
        path = run_dir / f"{name}.parquet"
        if path.is_file():
            try:
                history: list[dict[str, float]] = pd.read_parquet(path).to_dict("records")  # type: ignore[assignment]
            except Exception as exc:  # noqa: BLE001 (pyarrow raises several kinds for a damaged file)
                raise StafpipeError(f"plot.run_dir: {path} is not a readable table ({type(exc).__name__})") from None
            return {name: draw(history)}
    raise StafpipeError(f"plot.run_dir: {run_dir} holds no learning_curves.parquet or losses.parquet (a training run?)")


REPORT_FIGURES = "figures/reproduction"
"""Where the report's figures are copied, relative to REPRODUCTION.md (in the repo: docs/figures/reproduction/)."""


def figure_name(figure: Path) -> str:
    """A figure's name in the report: its study, its step (run number and config hash dropped) and its file, e.g.
    `staf_table1-fig4-circle-trajectories_episode_0000.png` for .../staf_table1/16-fig4-circle-806131ccd0/..."""
    step = re.sub(r"^\d+-|-[0-9a-f]{10}$", "", figure.parent.name)
    return f"{figure.parent.parent.name}-{step}-{figure.name}"


def _copier(source: Path) -> Callable[[Path], object]:
    """What `atomic_write` calls to copy `source` into its temporary file."""
    return lambda tmp: shutil.copyfile(source, tmp)


def _report(pc: PlotConfig, out_dir: Path) -> list[Path]:
    """REPRODUCTION.md and reproduction.csv over every run directory given (eval, ablate and plot runs; others are
    skipped); every run is read before anything is written."""
    from stafpipe.report.evidence import gather
    from stafpipe.report.render import judge_all, markdown, rows_frame

    evidence = gather([Path(d) for d in [pc.run_dir, *pc.run_dirs] if d])
    rows = judge_all(evidence)
    figures = {f"{REPORT_FIGURES}/{figure_name(f)}": f for f in evidence.figures}
    text = markdown(rows, list(figures))
    outputs = write_table(rows_frame(rows), out_dir / "reproduction")
    for name, source in figures.items():  # the report carries its figures: its links resolve wherever it is copied
        outputs.append(atomic_write(out_dir / name, _copier(source)))
    outputs.append(atomic_write(out_dir / "REPRODUCTION.md", lambda tmp: tmp.write_text(text)))
    print("\n".join(str(p) for p in outputs))
    return outputs


def _videos(pc: PlotConfig, source: Path, out_dir: Path) -> list[Path]:
    """`plot video`: an MP4 and/or GIF (`plot.video_formats`) per episode of an eval run (the first `max_episodes`),
    or of one episode's .mcap file. Every log is read before the first video is written, and each video is streamed
    into a temporary file renamed into place once whole."""
    from stafpipe.episode_log import read_episode
    from stafpipe.plots.video import episode_frames, write_video

    files = [source] if source.is_file() else _episode_logs(pc, source)
    records = [read_episode(f) for f in files]
    outputs: list[Path] = []
    for path, rec in zip(files, records, strict=True):
        final = {fmt: out_dir / f"video_{path.stem}.{fmt}" for fmt in pc.video_formats}
        # the encoders pick the container by the file's suffix, so the temporary file keeps it
        tmp = {fmt: p.with_name(f".{p.name}.tmp-{os.getpid()}.{fmt}") for fmt, p in final.items()}
        try:
            write_video(episode_frames(rec, pc.stride, pc.width_px), tmp, pc.fps)
            for fmt, p in final.items():
                os.replace(tmp[fmt], p)
                outputs.append(p)
        finally:
            for t in tmp.values():
                t.unlink(missing_ok=True)
        log.info("wrote the videos of %s", path.name)
    print("\n".join(str(p) for p in outputs))
    return outputs


def run_plot(cfg: DictConfig, out_dir: Path) -> list[Path]:
    """Draw `plot.kind` from `plot.run_dir`; every input is read and checked before the first figure is written."""
    pc = section(cfg.plot, PlotConfig)
    pc.check()
    run_dir = Path(pc.run_dir or pc.run_dirs[0])
    if pc.kind == "video" and run_dir.is_file():
        return _videos(pc, run_dir, out_dir)
    for d in [run_dir, *map(Path, pc.run_dirs)]:
        if not d.is_dir():
            raise StafpipeError(f"plot.run_dir: no such directory: {d}")
    outputs: list[Path] = []
    if pc.kind == "report":
        return _report(pc, out_dir)
    if pc.kind == "video":
        return _videos(pc, run_dir, out_dir)
    if pc.kind in ("timing", "table"):
        tables = _timing_tables(run_dir) if pc.kind == "timing" else _staf_tables(pc)  # all read before any write
        for name, text in tables.items():
            outputs.append(atomic_write(out_dir / name, lambda tmp, text=text: tmp.write_text(text)))  # type: ignore[misc]
        if pc.kind == "table":  # Fig. 8(e) beside the table
            from stafpipe.plots.staf_tables import cfi_sigma_figure

            table = pd.read_csv(out_dir / "table.csv", keep_default_na=False, na_values=[""])
            outputs += save_figure(cfi_sigma_figure(table), out_dir / "cfi_vs_sigma", pc.formats, pc.dpi)
            if "label" in table and table["label"].astype(str).str.len().gt(0).any():  # variants: the levels figure
                from stafpipe.plots.levels import levels_figure

                outputs += save_figure(
                    levels_figure(table.fillna({"label": ""})), out_dir / "levels", pc.formats, pc.dpi
                )
        print("\n".join(str(p) for p in outputs))
        return outputs
    if pc.kind == "adaptation":
        figures = _adaptation_figures(pc, run_dir, out_dir)
        for name, fig in figures.items():
            outputs += save_figure(fig, out_dir / name, pc.formats, pc.dpi)
        print("\n".join(str(p) for p in outputs))
        return outputs
    draw = {
        "trajectories": _trajectory_figures,
        "partitions": _partition_figures,
        "training": _training_figures,
        "connectivity": _connectivity_figures,
        "regions": _region_figures,
    }[pc.kind]
    for name, fig in draw(pc, run_dir).items():
        outputs += save_figure(fig, out_dir / name, pc.formats, pc.dpi)
        log.info("drew %s", name)
    print("\n".join(str(p) for p in outputs))
    return outputs
