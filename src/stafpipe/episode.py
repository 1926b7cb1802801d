"""One seeded episode of a method on a scenario: simulate, record, score, and log to MCAP.

`episode_context` derives what the metrics need from the scenario's geometry; `trajectory_from_record` rebuilds the
trajectory from an MCAP log so that `stafpipe inspect` recomputes exactly the metrics of the results table.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from stafpipe.controllers import Controller, TeamInfo
from stafpipe.controllers.plan_geometry import extent, lateral_clearance
from stafpipe.episode_log import EpisodeLogWriter, EpisodeRecord
from stafpipe.faults import ROBOT_FAULTS
from stafpipe.geometry import Geometry, PathFrame, capsule_arrays, closest_points, path_length
from stafpipe.interrupt import check as check_interrupt
from stafpipe.metrics import MetricContext, RouteProgress, Trajectory, episode_metrics, matched_goal_distance
from stafpipe.scenario import Scenario, ScenarioConfig, ScenarioError, build_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import STUCK_DISTANCE, WorldConfig, Worlds


def scenario_yaml(scenario: Scenario) -> str:
    """The scenario as YAML text (what the log stores)."""
    return OmegaConf.to_yaml(OmegaConf.structured(scenario.spec))


def scenario_from_yaml(text: str) -> Scenario:
    """Rebuild a scenario from `scenario_yaml` text."""
    spec = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(ScenarioConfig), OmegaConf.create(text)))
    return build_scenario(spec)  # type: ignore[arg-type]


def _route(scenario: Scenario) -> list[tuple[float, float]]:
    t = scenario.spec.team
    return [tuple(t.start), *[tuple(p) for p in scenario.spec.reference_path], tuple(t.goal)]


def team_path(scenario: Scenario, geometry: Geometry, clearance: float | None = None) -> np.ndarray:
    """The formation centre's shortest collision-free path from start to goal through the reference waypoints (K, 2),
    keeping `clearance` (default: one robot radius) from obstacles: with the default, what controllers get as
    TeamInfo.path."""
    route = _route(scenario)
    keep = scenario.spec.robot.radius if clearance is None else clearance
    legs = [geometry.shortest_path(a, b, keep) for a, b in itertools.pairwise(route)]
    return np.concatenate([legs[0], *[leg[1:] for leg in legs[1:]]])


def centred_path(scenario: Scenario, geometry: Geometry, passage_width: float) -> np.ndarray:
    """The centre's shortest path keeping almost half the narrowest passage from obstacles, so that it runs through the
    middle of every passage (what STAF's plan centres its subteams on); the TeamInfo.path if that is impossible (e.g.
    a start closer to a wall)."""
    for clearance in (passage_width / 2 - 0.05, passage_width / 2 - 0.2, passage_width / 4):
        if clearance > scenario.spec.robot.radius:
            try:
                return team_path(scenario, geometry, clearance)
            except ValueError:
                continue
    return team_path(scenario, geometry)


def episode_context(
    scenario: Scenario, geometry: Geometry, sensing: SensingConfig, goal_tolerance: float, cfi_margin: float
) -> tuple[MetricContext, np.ndarray]:
    """Metric context (eta and the travel-time lower bound from geometry) and the centre's shortest path."""
    t, r = scenario.spec.team, scenario.spec.robot
    route = _route(scenario)
    try:
        path = team_path(scenario, geometry)
    except ValueError:
        raise ScenarioError(
            f"team.goal {list(t.goal)}: no way there from team.start {list(t.start)} for a robot of radius {r.radius} "
            "(walls or obstacles close the map between them)"
        ) from None
    eta = min(geometry.passage_width(a, b) for a, b in itertools.pairwise(route))
    per_robot = float(np.linalg.norm(np.subtract(t.goal, t.start)))  # every slot moves by the centre's displacement
    lower_bound = max(path_length(path), per_robot) / r.max_speed
    ctx = MetricContext(
        path=tuple(map(tuple, path.tolist())),
        passages=narrow_stretches(scenario, geometry, path, cfi_margin),
        robot_radius=r.radius,
        formation=t.formation,
        spacing=t.spacing,
        angle_deg=t.angle_deg,
        heading_deg=t.heading_deg,
        passage_width=eta,
        travel_time_lower_bound=lower_bound,
        goal_tolerance=goal_tolerance,
        sensing_radius=sensing.radius,
        cfi_margin=cfi_margin,
        occlusion=sensing.occlusion,
        route=tuple(tuple(map(float, p)) for p in scenario.spec.reference_path),
    )
    return ctx, path


def narrow_stretches(scenario: Scenario, geometry: Geometry, path: np.ndarray, margin: float) -> tuple:
    """((from, to), ...) arc lengths along `path` where the free width straight across it, less `margin` on each
    side, is narrower than the whole team in its formation (slots' width across the heading plus a body): the
    passages a team must split or adapt its formation for. Sampled every 0.1 m; remembered per geometry."""
    frame, ds = PathFrame(path), 0.1
    points, heading = frame.at(np.arange(0.0, frame.length + ds, ds))
    key = ("free_width", points.tobytes(), heading.tobytes())
    width = geometry.remember(key, lambda: lateral_clearance(points, heading, scenario, both=True))
    narrow = width - 2 * margin < extent(scenario.template(), scenario.spec.robot.radius)[1]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], narrow.astype(int), [0]])))
    runs = zip(edges[::2], edges[1::2], strict=True)  # [first, last + 1) sample of each narrow run
    return tuple((round(float(a * ds), 6), round(float((b - 1) * ds), 6)) for a, b in runs)


def obstacle_distances(scenario: Scenario, positions: np.ndarray, movers: np.ndarray) -> np.ndarray:
    """(T, n) distance from each robot's surface to the nearest static or moving obstacle."""
    a, b, r = capsule_arrays(scenario)
    radius = scenario.spec.robot.radius
    mover_r = np.array([m.radius for m in scenario.spec.moving_obstacles])
    cp = closest_points(positions, a, b)  # (T, n, C, 2), every sample at once
    d = (np.linalg.norm(positions[:, :, None] - cp, axis=-1) - r).min(axis=-1)
    if len(mover_r):
        to_mover = np.linalg.norm(positions[:, :, None] - movers[:, None], axis=-1) - mover_r
        d = np.minimum(d, to_mover.min(axis=-1))
    return d - radius


def trajectory_from_record(rec: EpisodeRecord, scenario: Scenario) -> Trajectory:
    """The trajectory an MCAP log describes."""
    collisions = [(e["step"], e["robots"][0], e["robots"][1]) for e in rec.events if e["kind"] == "collision"]
    return Trajectory(
        time=rec.time,
        positions=rec.positions,
        velocities=rec.velocities,
        subteams=rec.subteams,
        team_goal=rec.goal,
        obstacle_distance=obstacle_distances(scenario, rec.positions, rec.movers),
        collisions=collisions,
    )


def run_episode(
    scenario: Scenario,
    geometry: Geometry,
    controller: Controller,
    method: str,
    seed: int,
    world_cfg: WorldConfig,
    sensing: SensingConfig,
    goal_tolerance: float = 0.3,
    cfi_margin: float = 0.1,
    log_path: Path | None = None,
) -> dict[str, float]:
    """Run one episode; log it to `log_path` (MCAP) if given; return its metrics."""
    return run_episodes(
        scenario, geometry, controller, method, [seed], world_cfg, sensing, goal_tolerance, cfi_margin, [log_path]
    )[0]


class Standstill:
    """Which worlds' teams have stood still for `stuck_time` (`WorldConfig.stuck_time`): no robot further than
    `STUCK_DISTANCE` from where it stood when the stretch began; any robot moving further starts a new stretch."""

    def __init__(self, pos: np.ndarray, stuck_time: float, dt: float) -> None:
        self.anchor = pos.copy()
        self.steps = np.zeros(len(pos), dtype=int)
        self.limit = int(round(stuck_time / dt)) if stuck_time > 0 else 0

    def update(self, pos: np.ndarray) -> np.ndarray:
        """Count one more step; the worlds (B,) whose stretch has reached `stuck_time` (none when off)."""
        moved = np.linalg.norm(pos - self.anchor, axis=-1).max(axis=-1) > STUCK_DISTANCE
        self.anchor[moved] = pos[moved]
        self.steps = np.where(moved, 0, self.steps + 1)
        return self.steps >= self.limit if self.limit else np.zeros(len(pos), dtype=bool)


class _Recorder:
    """What one world of a batch records while its episode runs, and its MCAP log if it has one."""

    def __init__(self, log_path: Path | None) -> None:
        self.log = EpisodeLogWriter(log_path) if log_path else None
        self.times: list[float] = []
        self.pos: list[np.ndarray] = []
        self.vel: list[np.ndarray] = []
        self.sub: list[np.ndarray] = []
        self.movers: list[np.ndarray] = []
        self.collisions: list[tuple[int, int, int]] = []

    def record(self, worlds: Worlds, w: int, controller: Controller, step: int) -> None:
        self.times.append(float(worlds.time[w]))
        self.pos.append(worlds.pos[w].copy())
        self.vel.append(worlds.vel[w].copy())
        self.sub.append(controller.subteams.copy())
        self.movers.append(worlds.mover_positions(w))
        if self.log:
            self.log.state(
                self.times[-1], self.pos[-1], self.vel[-1], worlds.heading[w], controller.targets, self.sub[-1],
                self.movers[-1],
            )  # fmt: skip
            for e in controller.drain_events():
                self.log.event(self.times[-1], step, e.kind, e.robots, e.detail)
            for kind, fault in worlds.fault_events:
                robots = [fault.robot] if fault.kind in ROBOT_FAULTS else []
                self.log.event(self.times[-1], step, kind, robots, fault.describe())

    def collided(self, step: int, a: int, b: int) -> None:
        self.collisions.append((step, a, b))
        if self.log:
            self.log.event(self.times[-1], step, "collision", [a, b])

    def trajectory(self, scenario: Scenario, goal: np.ndarray) -> Trajectory:
        p = np.stack(self.pos)
        return Trajectory(
            np.array(self.times),
            p,
            np.stack(self.vel),
            np.stack(self.sub),
            goal,
            obstacle_distances(scenario, p, np.stack(self.movers)),
            self.collisions,
        )


def run_episodes(
    scenario: Scenario,
    geometry: Geometry,
    controller: Controller,
    method: str,
    seeds: list[int],
    world_cfg: WorldConfig,
    sensing: SensingConfig,
    goal_tolerance: float = 0.3,
    cfi_margin: float = 0.1,
    log_paths: list[Path | None] | None = None,
) -> list[dict[str, float]]:
    """Run one episode per seed at once, in parallel worlds of one batch (world w seeded seeds[w]); log world w to
    `log_paths[w]` (MCAP) if given; return each episode's metrics. Each episode ends when its robots are home (or at
    the time limit); a finished world is no longer asked for actions nor recorded, and cannot touch the others (each
    world has its own space and random streams), so an episode's result does not depend on the batch it ran in."""
    ctx, path = episode_context(scenario, geometry, sensing, goal_tolerance, cfi_margin)
    worlds = Worlds([scenario] * len(seeds), sensing, world_cfg)
    obs = worlds.reset(list(seeds))
    template = scenario.template()
    controller.reset_worlds(
        [
            TeamInfo(scenario, obs.position[w].copy(), worlds.goal[w].copy(), template, path, ctx.passage_width)
            for w in range(len(seeds))
        ]
    )
    recorders = [_Recorder(p) for p in (log_paths or [None] * len(seeds))]
    text = scenario_yaml(scenario) if any(rec.log for rec in recorders) else ""
    for w, (rec, seed) in enumerate(zip(recorders, seeds, strict=True)):
        if rec.log:
            rec.log.info(method, seed, text, asdict(ctx), worlds.goal[w])
        rec.record(worlds, w, controller.world_view(w), 0)
    active = np.ones(len(seeds), dtype=bool)
    # the reference waypoints each world's team has passed, from its start on (as metrics.route_done counts them)
    route = RouteProgress([ctx.route] * len(seeds))
    route.update(worlds.pos)
    steps = int(round(scenario.spec.time_limit / world_cfg.control_dt))
    still = Standstill(worlds.pos, world_cfg.stuck_time, world_cfg.control_dt)
    for step in range(1, steps + 1):
        check_interrupt()  # Ctrl-C or SIGTERM: stop between steps (interrupt.py)
        actions = controller.act_worlds(obs, active)
        obs, events = worlds.step(actions)
        passed = route.update(worlds.pos)
        for w in np.flatnonzero(active).tolist():
            rec = recorders[w]
            rec.record(worlds, w, controller.world_view(w), step)
            for c in events[w]:
                rec.collided(step, c.a, c.b)
            if passed[w] and matched_goal_distance(worlds.pos[w], worlds.goal[w]).max() <= goal_tolerance:
                active[w] = False
        for w in np.flatnonzero(still.update(worlds.pos) & active).tolist():
            active[w] = False
            if log := recorders[w].log:
                log.event(recorders[w].times[-1], step, "stuck", [], f"{world_cfg.stuck_time:g} s still")
        if not active.any():
            break
    results = []
    for w, rec in enumerate(recorders):
        values = episode_metrics(rec.trajectory(scenario, worlds.goal[w].copy()), ctx)
        if rec.log:
            rec.log.metrics(rec.times[-1], values)
            rec.log.close()
        results.append(values)
    return results
