"""The simulated world: disc robots and obstacles in pymunk, B independent worlds stepped as one batch.

Each world owns one pymunk Space. A batch of B worlds behaves exactly like B single worlds (a test checks it): every
world has its own Space and its own random generator, and the batch only stacks their states to compute drives and
observations vectorized. Velocities go in and states come out through pymunk's batch API, not per-body attributes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pymunk
import pymunk.autogeometry
import pymunk.batch as pb
from pymunk._chipmunk import ffi as _ffi
from pymunk._chipmunk import lib as _cp

from stafpipe.drives import DRIVES
from stafpipe.errors import ConfigError
from stafpipe.faults import Fault, drop_probability, robots_hit, transitions
from stafpipe.formations import place
from stafpipe.geometry import capsule_arrays, obstacle_distance
from stafpipe.scenario import Scenario
from stafpipe.sensing import Observation, SensingConfig, observe

ROBOT, STATIC, MOVING = 1, 2, 3
_STATE_FIELDS = (pb.BodyFields.POSITION | pb.BodyFields.VELOCITY).value
_SET_BODIES = _ffi.addressof(_cp, "pmSpaceBodySetIteratorFuncBatched")
_GET_BODIES = _ffi.addressof(_cp, "pmSpaceBodyGetIteratorFuncBatched")
_FAR = 1e6  # padding capsules of worlds with fewer obstacles lie here


@dataclass
class WorldConfig:
    """Simulation settings (section `world`)."""

    control_dt: float = 0.1
    """Control period in seconds (one `step`)."""
    substeps: int = 4
    """Physics substeps per control period: 4 keep robot-robot overlaps to a few cm (measured on the 2-core development
    machine)."""
    collision_slop: float = 0.005
    """pymunk's allowed overlap; the default 0.1 lets robots leave walled boxes (measured on the 2-core development
    machine)."""
    start_noise: float = 0.12
    """Standard deviation (m) of the seeded perturbation of each robot's start position, clipped at 2 sigma; a robot
    whose perturbed start would touch an obstacle or another robot starts on its slot (docs/decisions.md)."""
    start_kick: float = 0.0
    """A disturbance for training (m): in an episode's first step each robot is carried, on top of its command, by up
    to this far in a random direction (its own seeded stream; contacts apply), and keeps only its commanded velocity
    afterwards. 0: none. An earlier simulator did this by accident (the STAF-planned journal (docs/staf_planned.md),
    "Eight seeds")."""
    heading_spread_deg: float = 0.0
    """Each episode turns the start formation about its centre by an angle drawn uniformly from +-this (degrees); a
    draw that puts a robot on an obstacle is redrawn (10 tries, then no turn). Goals stay where the scenario has
    them."""
    stuck_time: float = 20.0
    """s: an episode ends early once, for this long, no robot has moved more than `STUCK_DISTANCE` from where it
    stood when that stretch began (a team at a standstill short of its goal: its metrics are those of the moment it
    ended, its log records a `stuck` event). STAF's L&F rows (SR 40-70 % with TTs of 27-30 s, Table 1) imply that
    episodes of a stuck team ended so, not at a time limit; time-averaged metrics then do not average standing
    still. 0: off, every episode runs until its robots are home or its time limit."""
    faults: list[Fault] = field(default_factory=list)
    """Faults the world and its sensing inject (stafpipe.faults: stuck, silent, drop, dropout), the same for every
    method; e.g. `world.faults=[{kind: stuck, robot: 3, start: 8}]` (docs/faults.md, `stafpipe run faults`)."""

    def check(self, key: str = "world") -> None:
        from stafpipe.errors import require

        require(self.control_dt > 0, f"{key}.control_dt", "must be > 0", self.control_dt)
        require(self.substeps >= 1, f"{key}.substeps", "must be >= 1", self.substeps)
        require(self.collision_slop >= 0, f"{key}.collision_slop", "must be >= 0", self.collision_slop)
        require(self.start_noise >= 0, f"{key}.start_noise", "must be >= 0", self.start_noise)
        require(self.start_kick >= 0, f"{key}.start_kick", "must be >= 0", self.start_kick)
        require(0 <= self.stuck_time <= 3600, f"{key}.stuck_time", "must be in [0, 3600] s (0: off)", self.stuck_time)
        spread = self.heading_spread_deg
        require(0 <= spread <= 180, f"{key}.heading_spread_deg", "must be in [0, 180]", spread)
        for k, fault in enumerate(self.faults):
            fault.check(f"{key}.faults[{k}]")


STUCK_DISTANCE = 0.1
"""m: a robot that stays within this of where it stood is standing still (`WorldConfig.stuck_time`): more than the
jitter of a robot holding its place, less than a robot's radius."""


@dataclass
class Collision:
    """A contact that began during a step: robot `a` with robot `b`, or with an obstacle (`b` = -1)."""

    a: int
    b: int


class _BodyIO:
    """pymunk's batch body get/set, prepared once per space (what pymunk.batch does per call, without the per-call
    setup).

    `velocity_rows` (bodies, 2) is read by `set_velocities`; `state` (bodies, 4: x, y, vx, vy) is a view of a
    pymunk-owned
    array of exactly that size, refilled by `get_state`, so pymunk never grows (reallocates) it.
    """

    def __init__(self, space: pymunk.Space, bodies: int):
        self.handle = space._space
        self.velocity_rows = np.zeros((bodies, 2))
        self._set_arr = _ffi.new("pmFloatArray *")
        self._set_mem = _ffi.from_buffer("cpFloat[]", self.velocity_rows.reshape(-1))
        self._set_arr.arr, self._set_arr.max = self._set_mem, 2 * bodies
        self._set = _ffi.new("pmBatchedData *")
        self._set.fields, self._set.floatArray = pb.BodyFields.VELOCITY.value, self._set_arr
        # pymunk grows an array that is full or one short of full; two spare slots keep it from ever reallocating.
        self._get_arr = _ffi.gc(_cp.pmFloatArrayNew(4 * bodies + 2), _cp.pmFloatArrayFree)
        memory = self._get_arr.arr
        self._get = _ffi.new("pmBatchedData *")
        self._get.fields, self._get.floatArray = _STATE_FIELDS, self._get_arr
        self.state = np.frombuffer(_ffi.buffer(memory, 4 * bodies * _ffi.sizeof("cpFloat"))).reshape(bodies, 4)
        self.get_state()
        if self._get_arr.arr != memory or self._get_arr.num != 4 * bodies:
            raise RuntimeError("pymunk reallocated the body-state array; `state` would read freed memory")

    def set_velocities(self) -> None:
        self._set_arr.num = 0  # the set iterator reads from index `num` on
        _cp.cpSpaceEachBody(self.handle, _SET_BODIES, self._set)

    def get_state(self) -> None:
        self._get_arr.num = 0
        _cp.cpSpaceEachBody(self.handle, _GET_BODIES, self._get)


@dataclass
class _Space:
    """One pymunk space with the bodies of one world."""

    space: pymunk.Space
    robots: list[pymunk.Body]
    movers: list[pymunk.Body]
    robot_of: dict[pymunk.Shape, int]
    io: _BodyIO
    events: list[Collision] = field(default_factory=list)

    def place(self, robots: np.ndarray, movers: list[tuple[float, float]]) -> None:
        """Put the robots at rest and the movers at these places, with nothing carried over from before.

        Chipmunk moves a body at the start of each step by its velocity plus the position correction that the last
        step's contacts left it (`v_bias`), which nothing public resets: robots stacked at the origin when the space
        was built, or touching at the end of the last episode, were pushed apart by up to 0.3 m in an episode's first
        step. One step of 1e-9 s from the new places (where nothing touches) spends that correction, moving each body
        by less than 1e-7 m; the places are then set again exactly."""

        def put() -> None:
            for body, p in zip(self.robots, robots, strict=True):
                body.position, body.velocity = (float(p[0]), float(p[1])), (0.0, 0.0)
            for body, q in zip(self.movers, movers, strict=True):
                body.position = q

        put()
        _cp.cpSpaceStep(self.io.handle, 1e-9)
        put()
        self.events.clear()

    def step(self, dt: float, substeps: int) -> None:
        """Hand the velocities to pymunk, advance `substeps` substeps of `dt / substeps`, read the state back."""
        self.io.set_velocities()
        # Space.step only adds deferred add/remove and post-step callbacks (unused here) around cpSpaceStep;
        # calling it directly halves the per-substep cost. Space.step ran once at build time to check the bodies.
        handle, h = self.io.handle, dt / substeps
        for _ in range(substeps):
            _cp.cpSpaceStep(handle, h)
        self.io.get_state()


def _build_space(scenario: Scenario, n: int, cfg: WorldConfig) -> _Space:
    space = pymunk.Space()
    space.collision_slop = cfg.collision_slop
    r = scenario.spec.robot.radius
    robots: list[pymunk.Body] = []
    robot_of: dict[pymunk.Shape, int] = {}
    for i in range(n):
        body = pymunk.Body(1.0, math.inf)
        shape: pymunk.Shape = pymunk.Circle(body, r)
        shape.collision_type, shape.friction, shape.elasticity = ROBOT, 0.0, 0.0
        space.add(body, shape)
        robots.append(body)
        robot_of[shape] = i
    for poly in scenario.polygons:
        parts = [poly]
        if len(pymunk.Poly(None, poly.tolist()).get_vertices()) != len(poly):  # concave: split into convex parts
            parts = [
                np.array(p) for p in pymunk.autogeometry.convex_decomposition(poly.tolist() + [poly[0].tolist()], 0.01)
            ]
        for part in parts:
            shape = pymunk.Poly(space.static_body, [tuple(p) for p in part])
            shape.collision_type = STATIC
            space.add(shape)
    for cap in scenario.capsules:
        shape = pymunk.Segment(space.static_body, cap.a, cap.b, cap.radius)
        shape.collision_type = STATIC
        space.add(shape)
    movers = []
    for m in scenario.spec.moving_obstacles:
        body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        shape = pymunk.Circle(body, m.radius)
        shape.collision_type = MOVING
        space.add(body, shape)
        movers.append(body)
    probe = pb.Buffer()  # how many bodies the batch API iterates (robots first, then movers, then the static body)
    pb.get_space_bodies(space, pb.BodyFields.BODY_ID, probe)
    ids = np.frombuffer(probe.int_buf(), dtype=np.uintp)
    if list(ids[: n + len(movers)]) != [b.id for b in robots + movers]:
        raise RuntimeError("pymunk iterates bodies in an unexpected order")
    space.step(1e-9)  # lets pymunk validate the bodies once; `_Space.place` spends the correction this leaves
    out = _Space(space, robots, movers, robot_of, _BodyIO(space, len(ids)))

    def robot_robot(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
        a, b = (robot_of[s] for s in arbiter.shapes)
        out.events.append(Collision(min(a, b), max(a, b)))

    def robot_obstacle(arbiter: pymunk.Arbiter, _space: pymunk.Space, _data: object) -> None:
        out.events.append(Collision(robot_of[arbiter.shapes[0]], -1))

    space.on_collision(ROBOT, ROBOT, begin=robot_robot)
    space.on_collision(ROBOT, STATIC, begin=robot_obstacle)
    space.on_collision(ROBOT, MOVING, begin=robot_obstacle)
    return out


def _clear_jitter(start: np.ndarray, jitter: np.ndarray, scenario: Scenario) -> np.ndarray:
    """The jitter, zeroed for every robot whose perturbed start would touch an obstacle or a robot (so the perturbation
    never makes a start invalid that was valid unperturbed); repeated until no perturbed robot touches anything, so
    the result depends only on the draw."""
    r = scenario.spec.robot.radius
    jitter = jitter.copy()
    if not jitter.any():
        return jitter
    blocked = obstacle_distance(start + jitter, scenario) <= r
    jitter[blocked] = 0.0
    while True:
        pos = start + jitter
        gap = np.linalg.norm(pos[:, None] - pos[None], axis=-1) + np.eye(len(pos)) * 1e9
        moved = jitter.any(axis=1)
        touching = (gap <= 2 * r).any(axis=1) & moved
        if not touching.any():
            return jitter
        jitter[touching] = 0.0


class Worlds:
    """B independent worlds of the same team size; `Worlds([scenario])` is one world."""

    def __init__(self, scenarios: list[Scenario], sensing: SensingConfig | None = None, cfg: WorldConfig | None = None):
        self.cfg = cfg or WorldConfig()
        self.sensing = sensing or SensingConfig()
        self.scenarios = scenarios
        self.n = scenarios[0].spec.team.n
        if any(s.spec.team.n != self.n for s in scenarios):
            raise ValueError("all worlds of a batch need the same team size")
        self.robot = scenarios[0].spec.robot
        if any(s.spec.robot != self.robot for s in scenarios):
            raise ValueError("all worlds of a batch need the same robot")
        self.drive = DRIVES[self.robot.drive]
        self.faults = list(self.cfg.faults)
        for k, fault in enumerate(self.faults):
            if fault.robot >= self.n and fault.kind != "drop":
                raise ConfigError(f"world.faults[{k}].robot must be a robot index in [0, {self.n}), got {fault.robot}")
        self.fault_events: list[tuple[str, Fault]] = []
        """Faults that began or ended during the last reset or step (the same in every world: one clock)."""
        self.spaces = [_build_space(s, self.n, self.cfg) for s in scenarios]
        caps = [capsule_arrays(s) for s in scenarios]
        c_max = max(len(c[2]) for c in caps) + max(len(s.spec.moving_obstacles) for s in scenarios)
        b = len(scenarios)
        self.seg_a = np.full((b, c_max, 2), _FAR)
        self.seg_b = np.full((b, c_max, 2), _FAR)
        self.seg_r = np.zeros((b, c_max))
        for w, (a, bb, r) in enumerate(caps):
            self.seg_a[w, : len(r)], self.seg_b[w, : len(r)], self.seg_r[w, : len(r)] = a, bb, r
        self._mover_slots = [(len(c[2]), s.spec.moving_obstacles) for c, s in zip(caps, scenarios, strict=True)]
        self.pos = np.zeros((b, self.n, 2))
        self.vel = np.zeros((b, self.n, 2))
        self.heading = np.zeros((b, self.n))
        self.goal = np.zeros((b, self.n, 2))
        self.time = np.zeros(b)
        self.collided = np.zeros((b, self.n), dtype=bool)
        self.rngs = [np.random.default_rng(0) for _ in scenarios]
        self._kick: np.ndarray | None = None
        """Each robot's extra velocity in the next step (`start_kick`), set by reset and spent by step."""
        self.fault_rngs = [np.random.default_rng(0) for _ in scenarios]
        """Lost messages are drawn from their own streams: a drop fault leaves the sensing noise as it was."""
        self._mover_state: list[list[tuple[np.ndarray, int]]] = [[] for _ in scenarios]
        self._has_movers = [w for w, (_, specs) in enumerate(self._mover_slots) if specs]
        self.movers = np.zeros((b, max(len(specs) for _, specs in self._mover_slots), 4))
        self.movers[..., :2] = _FAR

    @property
    def size(self) -> int:
        """Number of worlds B."""
        return len(self.spaces)

    def reset(self, seeds: list[int], formations: list[np.ndarray] | None = None) -> Observation:
        """Start every world from its scenario's start formation, perturbed by its seed.

        `formations` optionally gives each world's template slots (n, 2) instead of the scenario's own formation.
        """
        for w, (seed, sc) in enumerate(zip(seeds, self.scenarios, strict=True)):
            team = sc.spec.team
            slots = formations[w] if formations is not None else sc.template()
            h = math.radians(team.heading_deg)
            rng = np.random.default_rng(seed)
            self.rngs[w] = rng
            self.fault_rngs[w] = np.random.default_rng([seed, 1])
            jitter = np.clip(
                rng.normal(0.0, self.cfg.start_noise, (self.n, 2)), -2 * self.cfg.start_noise, 2 * self.cfg.start_noise
            )
            start, turn = self._turned_start(sc, place(slots, np.asarray(team.start), h), seed)
            self.pos[w] = start + _clear_jitter(start, jitter, sc)
            self.goal[w] = place(slots, np.asarray(team.goal), h)
            self.vel[w] = 0.0
            self.heading[w] = h + turn  # a turned team faces the turned way (differential drive)
            self.time[w] = 0.0
            self.collided[w] = False
            movers = sc.spec.moving_obstacles
            self.spaces[w].place(self.pos[w], [tuple(m.waypoints[0]) for m in movers])
            self._mover_state[w] = [(np.array(m.waypoints, dtype=float), 1 % len(m.waypoints)) for m in movers]
        self._update_movers()
        self.fault_events = transitions(self.faults, -1.0, 0.0)
        self._kick = self._draw_kick(seeds) if self.cfg.start_kick > 0 else None
        return self.observe()

    def _draw_kick(self, seeds: list[int]) -> np.ndarray:
        """(B, n, 2) velocities that carry each robot up to `start_kick` m in one control period, uniform in direction
        and in distance, from each episode's own stream (so a kick of 0 leaves every other draw as it was)."""
        kick = np.zeros((len(seeds), self.n, 2))
        for w, seed in enumerate(seeds):
            rng = np.random.default_rng([seed, 3])
            angle, dist = rng.uniform(0, 2 * math.pi, self.n), rng.uniform(0, self.cfg.start_kick, self.n)
            kick[w] = np.stack([np.cos(angle), np.sin(angle)], axis=1) * (dist / self.cfg.control_dt)[:, None]
        return kick

    def _turned_start(self, sc: Scenario, start: np.ndarray, seed: int) -> tuple[np.ndarray, float]:
        """The start slots turned about their centre by the episode's draw from +-`heading_spread_deg` (its own random
        stream, so that a spread of 0 leaves every other draw as it was), and the angle (rad)."""
        if self.cfg.heading_spread_deg <= 0:
            return start, 0.0
        rng, spread = np.random.default_rng([seed, 2]), math.radians(self.cfg.heading_spread_deg)
        centre = start.mean(axis=0)
        for _ in range(10):
            a = rng.uniform(-spread, spread)
            turn = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            turned = centre + (start - centre) @ turn.T
            if (obstacle_distance(turned, sc) > sc.spec.robot.radius).all():
                return turned, a
        return start, 0.0

    def _update_movers(self) -> None:
        for w, (first, specs) in enumerate(self._mover_slots):
            for k, (body, m) in enumerate(zip(self.spaces[w].movers, specs, strict=True)):
                p = np.array(body.position)
                self.seg_a[w, first + k] = self.seg_b[w, first + k] = p
                self.seg_r[w, first + k] = m.radius
                self.movers[w, k] = (*p, *body.velocity)

    def _mover_velocity(self, w: int, k: int, body: pymunk.Body) -> tuple[float, float]:
        waypoints, target = self._mover_state[w][k]
        m = self.scenarios[w].spec.moving_obstacles[k]
        p = np.array(body.position)
        delta = waypoints[target] - p
        dist = float(np.linalg.norm(delta))
        if dist < m.speed * self.cfg.control_dt:  # reached: head for the next waypoint (or stop at the last)
            if target + 1 < len(waypoints) or m.loop:
                self._mover_state[w][k] = (waypoints, (target + 1) % len(waypoints))
            return (delta[0] / self.cfg.control_dt, delta[1] / self.cfg.control_dt)
        return tuple(delta / dist * m.speed)

    def step(self, actions: np.ndarray) -> tuple[Observation, list[list[Collision]]]:
        """Apply commanded planar velocities (B, n, 2) for one control period.

        Returns the new observations and, per world, the contacts that began during the step.
        """
        dt = self.cfg.control_dt
        actions = np.array(actions, dtype=float)
        if self.faults:  # a stuck robot's actuators ignore its command
            actions[:, robots_hit(self.faults, "stuck", float(self.time[0]), self.n)] = 0.0
        self.vel, self.heading = self.drive(actions, self.vel, self.heading, self.robot, dt)
        events: list[list[Collision]] = []
        n, substeps = self.n, self.cfg.substeps
        kick, self._kick = self._kick, None
        for w, sp in enumerate(self.spaces):
            sp.io.velocity_rows[:n] = self.vel[w] if kick is None else self.vel[w] + kick[w]
        for w in self._has_movers:
            sp = self.spaces[w]
            for k, body in enumerate(sp.movers):
                sp.io.velocity_rows[n + k] = self._mover_velocity(w, k, body)
        for w, sp in enumerate(self.spaces):
            sp.step(dt, substeps)
            events.append(sp.events)
            if sp.events:
                for e in sp.events:
                    self.collided[w, e.a] = True
                    if e.b >= 0:
                        self.collided[w, e.b] = True
                sp.events = []
        state = np.stack([sp.io.state[:n] for sp in self.spaces])
        commanded = self.vel
        self.pos, self.vel = state[..., :2].copy(), state[..., 2:].copy()
        if kick is not None:  # the kick moves the robots once; their velocity stays the commanded one
            self.vel = commanded
        self.time += dt
        if self.faults:
            self.fault_events = transitions(self.faults, float(self.time[0]) - dt, float(self.time[0]))
        if self._has_movers:
            self._update_movers()
        return self.observe(), events

    def observe(self) -> Observation:
        """Observations of every robot of every world, with the active sensing and communication faults applied."""
        obs = self._sense()
        if not self.faults:
            return obs
        t, n = float(self.time[0]), self.n
        others = ~np.eye(n, dtype=bool)
        blind = robots_hit(self.faults, "dropout", t, n)  # they sense nothing (but still talk)
        obs.neighbours[:, blind, :] = False
        far = np.stack([np.cos(obs.heading), np.sin(obs.heading)], axis=-1) * 1e3
        obs.obstacle[:, blind] = far[:, blind]
        obs.obstacle_distance[:, blind] = 1e3
        silent = robots_hit(self.faults, "silent", t, n)  # nobody hears them
        obs.heard[..., silent] &= ~others[:, silent]
        p = drop_probability(self.faults, t)
        if p > 0:
            obs.heard[...] &= np.stack([r.random((n, n)) >= p for r in self.fault_rngs])
        return obs

    def _sense(self) -> Observation:
        return observe(
            self.pos,
            self.vel,
            self.heading,
            self.goal,
            self.time.copy(),
            self.seg_a,
            self.seg_b,
            self.seg_r,
            self.robot.radius,
            self.sensing,
            self.rngs,
            self.movers.copy(),
        )

    def mover_positions(self, w: int) -> np.ndarray:
        """Positions (M, 2) of world w's moving obstacles."""
        return np.array([tuple(b.position) for b in self.spaces[w].movers]).reshape(-1, 2)
