"""Episode videos (`stafpipe plot video`): one frame per `stride` logged states of an episode MCAP log, showing the
map, the team's path with its passages, every robot as a disc of its true radius coloured by its subteam with its
heading, the team's goals and each robot's current target (the controller's, where it has one), the moving obstacles,
a clock and the last split or merge. Frames are drawn by matplotlib's Agg canvas with the map drawn once (blitting)
and handed to the encoders one at a time: the MP4 encoder streams them to ffmpeg, the GIF encoder (Pillow) keeps
every frame until it writes the file (docs/usage.md, "Videos")."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.figure import Figure

from stafpipe.episode import scenario_from_yaml
from stafpipe.episode_log import EpisodeRecord
from stafpipe.geometry import PathFrame
from stafpipe.plots.trajectories import SUBTEAM_COLOURS, draw_map

MACRO_BLOCK = 16
"""Pixels: an H.264 encoder codes 16 x 16 blocks, so every frame's sides are a multiple of it (ffmpeg would otherwise
rescale each frame)."""


def frame_indices(steps: int, stride: int) -> list[int]:
    """The logged states a video shows: every `stride`-th from the first, and the last (where the episode ends)."""
    picked = list(range(0, steps, stride))
    if picked and picked[-1] != steps - 1:
        picked.append(steps - 1)
    return picked


def _passage_segments(path: np.ndarray, passages: Any) -> list[np.ndarray]:
    """The stretches of the team's `path` (K, 2) inside a passage (`MetricContext.passages`), as (k, 2) polylines."""
    if len(path) < 2:
        return []
    frame = PathFrame(path)
    out = []
    for lo, hi in passages:
        s = np.linspace(float(lo), float(hi), 24)
        points, _ = frame.at(s)
        out.append(np.asarray(points))
    return out


def _event_lines(rec: EpisodeRecord) -> list[tuple[float, str]]:
    """(time, caption) of every split and merge, in order."""
    return [(float(e["time"]), f"{e['kind']}: {e['detail']}") for e in rec.events if e["kind"] in ("split", "merge")]


class _Frames:
    """The figure of one episode, its map drawn once; `draw(k)` paints logged state k and returns its RGB pixels."""

    def __init__(self, rec: EpisodeRecord, width_px: int) -> None:
        scenario = scenario_from_yaml(rec.scenario_yaml)
        w = scenario.spec.world
        dpi = 100
        aspect = (w.ymax - w.ymin) / (w.xmax - w.xmin)
        width = max(MACRO_BLOCK, width_px // MACRO_BLOCK * MACRO_BLOCK)
        height = max(MACRO_BLOCK * 8, math.ceil(width * aspect / MACRO_BLOCK) * MACRO_BLOCK + MACRO_BLOCK * 3)
        self.fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        ax = self.fig.add_axes((0.04, 0.03, 0.94, 0.86))
        draw_map(ax, scenario)
        ax.set_xticks([])
        ax.set_yticks([])
        path = np.asarray(rec.context.get("path", ()), float)
        if len(path) >= 2:
            ax.plot(path[:, 0], path[:, 1], color="0.75", lw=1.0, ls=":")
        for k, seg in enumerate(_passage_segments(path, rec.context.get("passages", ()))):
            ax.plot(seg[:, 0], seg[:, 1], color="tab:orange", lw=4.0, alpha=0.35, label="passage" if k == 0 else None)
        ax.scatter(rec.goal[:, 0], rec.goal[:, 1], s=18, marker="x", color="k", linewidths=0.8, label="goal")
        radius = float(rec.context.get("robot_radius", 0.1))
        n = rec.positions.shape[1]
        self.robots = EllipseCollection(
            widths=np.full(n, 2 * radius),
            heights=np.full(n, 2 * radius),
            angles=np.zeros(n),
            units="xy",
            offsets=rec.positions[0],
            offset_transform=ax.transData,
            edgecolors="k",
            linewidths=0.4,
            animated=True,
        )
        ax.add_collection(self.robots)
        self.aims = ax.scatter([], [], s=14, marker="+", linewidths=0.9, animated=True, label="target")
        self.heads = LineCollection([], colors="k", linewidths=0.8, animated=True)
        ax.add_collection(self.heads)
        movers = scenario.spec.moving_obstacles
        m = rec.movers.shape[1]
        mover_radii = np.array([mv.radius for mv in movers][:m] + [radius] * max(0, m - len(movers)))
        self.movers = EllipseCollection(
            widths=2 * mover_radii,
            heights=2 * mover_radii,
            angles=np.zeros(m),
            units="xy",
            offsets=rec.movers[0] if m else np.zeros((0, 2)),
            offset_transform=ax.transData,
            facecolors="0.25",
            animated=True,
        )
        ax.add_collection(self.movers)
        ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
        title = f"{rec.method} on {scenario.spec.name}, seed {rec.seed}"
        self.fig.text(0.04, 0.955, title, fontsize=9, va="center")
        self.clock = self.fig.text(0.98, 0.955, "", fontsize=9, va="center", ha="right", animated=True)
        self.caption = self.fig.text(0.04, 0.915, "", fontsize=8, va="center", color="0.25", animated=True)
        self.radius, self.rec, self.ax = radius, rec, ax
        self.events = _event_lines(rec)
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.fig.bbox)
        self.size = (height, width)

    def draw(self, k: int) -> np.ndarray:
        rec = self.rec
        pos = rec.positions[k]
        self.canvas.restore_region(self.background)
        self.robots.set_offsets(pos)
        self.robots.set_facecolor([SUBTEAM_COLOURS[int(s) % len(SUBTEAM_COLOURS)] for s in rec.subteams[k]])
        tip = pos + 1.8 * self.radius * np.stack([np.cos(rec.headings[k]), np.sin(rec.headings[k])], -1)
        self.heads.set_segments(list(np.stack([pos, tip], axis=1)))
        if rec.movers.shape[1]:
            self.movers.set_offsets(rec.movers[k])
        t = float(rec.time[k])
        teams = len(np.unique(rec.subteams[k]))
        self.clock.set_text(f"t = {t:5.1f} s   {teams} subteam{'s' if teams > 1 else ''}")
        past = [text for when, text in self.events if when <= t + 1e-9]
        self.caption.set_text(past[-1] if past else "")
        aims = rec.targets[k]
        shown = np.isfinite(aims).all(axis=1) & (np.linalg.norm(aims - pos, axis=1) > self.radius)
        self.aims.set_offsets(aims[shown] if shown.any() else np.zeros((0, 2)))
        self.aims.set_color([SUBTEAM_COLOURS[int(s) % len(SUBTEAM_COLOURS)] for s in rec.subteams[k][shown]])
        for collection in (self.aims, self.robots, self.heads, self.movers):
            self.ax.draw_artist(collection)
        for text in (self.clock, self.caption):
            self.fig.draw_artist(text)
        pixels = np.asarray(self.canvas.buffer_rgba())[..., :3]
        return np.ascontiguousarray(pixels)


def episode_frames(rec: EpisodeRecord, stride: int = 1, width_px: int = 960) -> Iterator[np.ndarray]:
    """(H, W, 3) uint8 frames of an episode, one per `frame_indices(steps, stride)`."""
    frames = _Frames(rec, width_px)
    for k in frame_indices(len(rec.time), stride):
        yield frames.draw(k)


def write_video(frames: Iterator[np.ndarray], targets: dict[str, Path], fps: float) -> None:
    """Stream `frames` into every file of `targets` (format -> path; `mp4`: H.264 through imageio-ffmpeg's bundled
    ffmpeg, `gif`: Pillow, looping), one frame at a time."""
    import imageio.v2 as imageio

    with contextlib.ExitStack() as stack:
        writers: list[Any] = []
        for fmt, path in targets.items():
            if fmt == "mp4":
                kwargs: dict[str, Any] = {"format": "FFMPEG", "fps": fps, "codec": "libx264", "quality": 7}
                kwargs["macro_block_size"] = MACRO_BLOCK
            else:
                kwargs = {"format": "GIF", "duration": 1000.0 / fps, "loop": 0}
            writers.append(stack.enter_context(imageio.get_writer(path, mode="I", **kwargs)))
        for frame in frames:
            for writer in writers:
                writer.append_data(frame)
