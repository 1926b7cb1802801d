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
from stafpipe.episode_log import EpisodeLogWriter, EpisodeRecord
from stafpipe.faults import ROBOT_FAULTS
from stafpipe.geometry import Geometry, capsule_arrays, closest_points, path_length
from stafpipe.metrics import MetricContext, Trajectory, episode_metrics, matched_goal_distance
from stafpipe.scenario import Scenario, ScenarioConfig, ScenarioError, build_scenario
from stafpipe.sensing import SensingConfig
from stafpipe.world import WorldConfig, Worlds


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
    )
    return ctx, path


def obstacle_distances(scenario: Scenario, positions: np.ndarray, movers: np.ndarray) -> np.ndarray:
    """(T, n) distance from each robot's surface to the nearest static or moving obstacle."""
    a, b, r = capsule_arrays(scenario)
    radius = scenario.spec.robot.radius
    mover_r = np.array([m.radius for m in scenario.spec.moving_obstacles])
    out = np.empty(positions.shape[:2])
    for k, p in enumerate(positions):
        cp = closest_points(p, a, b)
        d = (np.linalg.norm(p[:, None] - cp, axis=-1) - r).min(axis=1)
        if len(mover_r):
            d = np.minimum(d, (np.linalg.norm(p[:, None] - movers[k][None], axis=-1) - mover_r).min(axis=1))
        out[k] = d - radius
    return out


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
    ctx, path = episode_context(scenario, geometry, sensing, goal_tolerance, cfi_margin)
    worlds = Worlds([scenario], sensing, world_cfg)
    obs = worlds.reset([seed]).world(0)
    controller.reset(
        TeamInfo(scenario, obs.position.copy(), worlds.goal[0].copy(), scenario.template(), path, ctx.passage_width)
    )
    log = EpisodeLogWriter(log_path) if log_path else None
    if log:
        log.info(method, seed, scenario_yaml(scenario), asdict(ctx), worlds.goal[0])
    times, pos, vel, sub, movers, collisions = [], [], [], [], [], []

    def record(step: int) -> None:
        times.append(float(worlds.time[0]))
        pos.append(worlds.pos[0].copy())
        vel.append(worlds.vel[0].copy())
        sub.append(controller.subteams.copy())
        movers.append(worlds.mover_positions(0))
        if log:
            log.state(times[-1], pos[-1], vel[-1], worlds.heading[0], controller.targets, sub[-1], movers[-1])
            for e in controller.drain_events():
                log.event(times[-1], step, e.kind, e.robots, e.detail)

    def log_faults(step: int) -> None:
        if log is None:
            return
        for kind, fault in worlds.fault_events:
            log.event(times[-1], step, kind, [fault.robot] if fault.kind in ROBOT_FAULTS else [], fault.describe())

    record(0)
    log_faults(0)
    steps = int(round(scenario.spec.time_limit / world_cfg.control_dt))
    for step in range(1, steps + 1):
        actions = controller.act(obs)
        obs_b, events = worlds.step(actions[None])
        obs = obs_b.world(0)
        record(step)
        log_faults(step)
        for c in events[0]:
            collisions.append((step, c.a, c.b))
            if log:
                log.event(times[-1], step, "collision", [c.a, c.b])
        if matched_goal_distance(worlds.pos[0], worlds.goal[0]).max() <= goal_tolerance:
            break
    p = np.stack(pos)
    mv = np.stack(movers)
    traj = Trajectory(
        np.array(times),
        p,
        np.stack(vel),
        np.stack(sub),
        worlds.goal[0].copy(),
        obstacle_distances(scenario, p, mv),
        collisions,
    )
    values = episode_metrics(traj, ctx)
    if log:
        log.metrics(times[-1], values)
        log.close()
    return values
