"""Plans for the STAF tests: a built-in scenario with another team, a team at its start with its plan, and the plan
driven alone by robots that move straight to their targets."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from stafpipe.controllers.plan_config import PlanConfig
from stafpipe.controllers.staf_plan import StafPlan
from stafpipe.episode import centred_path, episode_context
from stafpipe.formations import place
from stafpipe.geometry import Geometry, obstacle_distance
from stafpipe.scenario import build_scenario
from stafpipe.scenario_pool import load_named_scenario
from stafpipe.sensing import SensingConfig


def scenario_with(name: str, kind: str, n: int | None = None):
    sc = load_named_scenario(name)
    team = dataclasses.replace(sc.spec.team, formation=kind, n=n or sc.spec.team.n)
    return build_scenario(dataclasses.replace(sc.spec, team=team))


def start_and_plan(sc, divide, plan_cfg: PlanConfig) -> tuple[np.ndarray, StafPlan]:
    """The team's start positions and a plan for it from its start to its goal along the centred path."""
    geometry = Geometry(sc)
    ctx, _ = episode_context(sc, geometry, SensingConfig(), 0.3, 0.1)
    t = sc.spec.team
    pos = place(sc.template(), t.start, math.radians(t.heading_deg))
    goal = place(sc.template(), t.goal, math.radians(t.heading_deg))
    path = centred_path(sc, geometry, ctx.passage_width)
    return pos, StafPlan(plan_cfg, sc, sc.template(), goal, path, ctx.passage_width, divide)


def ideal_run(sc, divide, steps: int = 1500, plan_cfg: PlanConfig | None = None):
    """Robots that move straight to their plan targets at the robot's max speed: the plan alone, no policy."""
    geometry = Geometry(sc)
    ctx, _ = episode_context(sc, geometry, SensingConfig(), 0.3, 0.1)
    path = centred_path(sc, geometry, ctx.passage_width)
    t, v = sc.spec.team, sc.spec.robot.max_speed
    pos, goal = (
        place(sc.template(), t.start, math.radians(t.heading_deg)),
        place(sc.template(), t.goal, math.radians(t.heading_deg)),
    )
    plan = StafPlan(plan_cfg or PlanConfig(), sc, sc.template(), goal, path, ctx.passage_width, divide)
    log = {"events": [], "min_gap": np.inf, "min_wall": np.inf, "labels": [], "progress": []}
    for k in range(steps):
        target = plan.step(pos, 0.1)
        log["labels"].append(plan.labels.copy())
        log["progress"].append(plan.frame.progress(pos))
        log["events"] += [e[0] for e in plan.drain_events()]
        d = target - pos
        pos = pos + d * np.minimum(1.0, 0.1 * v / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9))
        gaps = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(len(pos)) * 9
        log["min_gap"] = min(log["min_gap"], gaps.min() - 2 * sc.spec.robot.radius)
        log["min_wall"] = min(log["min_wall"], (obstacle_distance(pos, sc) - sc.spec.robot.radius).min())
        if np.linalg.norm(pos - plan.goal, axis=1).max() < 0.05:
            return k * 0.1, log, ctx
    return math.inf, log, ctx
