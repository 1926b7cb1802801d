"""Seeded procedural training maps (`stafpipe generate-maps`): corridors, bridges, doorways, bends and S-bends,
several parallel gaps, bollard rows and obstacle fields, each with a random team (size, formation, drive).

STAF trains its policy in simulation and tests it on corridors, bridges, doorways and outdoor bollards/forests (STAF
Sec. 4, App. F). The built-in maps of `conf/scenario/` are test maps and are never trained on; a learned method
trains on these generated maps instead, so that what it learned is not the shape of the map it is scored on
(docs/decisions.md).

Every map is a plain scenario (`scenario.ScenarioConfig`), written as a scenario YAML that `scenario.path=` reads. The
team travels along +x from a free start area to a free goal area; the obstacles lie between them. A map is kept only if
the geometry finds a route for a robot from start to goal (otherwise another is drawn from the same generator).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from stafpipe.errors import require
from stafpipe.formations import FORMATION_TYPES, formation_slots
from stafpipe.scenario import RobotSpec, ScenarioConfig, TeamSpec, WorldBounds, build_scenario

FAMILIES = ("corridor", "bridge", "doorway", "bend", "s_bend", "gaps", "bollards", "field")
DRIVE_KINDS = ("holonomic", "diff_drive")


@dataclass
class MapsConfig:
    """Section `maps` of `stafpipe generate-maps` (and of `train_ppo.maps`): what the generator draws from."""

    count: int = 96
    """Maps to generate."""
    families: list[str] = field(default_factory=lambda: list(FAMILIES))
    """Map families, drawn uniformly: corridor, bridge, doorway, bend, s_bend, gaps, bollards, field."""
    width: list[float] = field(default_factory=lambda: [0.9, 3.5])
    """Range (m) of passage widths (corridors, bridges, doors, bends, gaps); bollard gaps are drawn from the low end."""
    length: list[float] = field(default_factory=lambda: [1.0, 12.0])
    """Range (m) of passage lengths (corridors, bridges, bends)."""
    team_sizes: list[int] = field(default_factory=lambda: [4, 12])
    """Inclusive range [low, high] of team sizes."""
    formations: list[str] = field(default_factory=lambda: ["circle", "wedge", "line", "square", "t", "v"])
    """Team formations, drawn uniformly (every formation type by default)."""
    drives: list[str] = field(default_factory=lambda: list(DRIVE_KINDS))
    """Robot drives, drawn uniformly."""
    spacing: float = 1.0
    """The team's nominal spacing (m), as in STAF's corridor."""
    turns: bool = False
    """True: each map is turned by a quarter turn drawn from {0, 90, 180, 270} degrees (world, obstacles, team and its
    heading together), so the team travels east, north, west or south; false: every team travels east (+x), as the
    shipped policy's training maps (docs/scenarios.md)."""

    def check(self, key: str = "maps") -> None:
        require(self.count >= 1, f"{key}.count", "must be >= 1", self.count)
        require(
            len(self.families) > 0 and all(f in FAMILIES for f in self.families),
            f"{key}.families",
            f"must be a non-empty list of {list(FAMILIES)}",
            self.families,
        )
        for name, low in (("width", 0.5), ("length", 0.2)):
            lo_hi = list(getattr(self, name))
            require(
                len(lo_hi) == 2 and low <= lo_hi[0] <= lo_hi[1],
                f"{key}.{name}",
                f"must be [low, high] with {low} <= low <= high",
                lo_hi,
            )
        sizes = list(self.team_sizes)
        require(
            len(sizes) == 2 and 2 <= sizes[0] <= sizes[1] <= 16,
            f"{key}.team_sizes",
            "must be [low, high] with 2 <= low <= high <= 16",
            sizes,
        )
        require(
            len(self.formations) > 0 and all(f in FORMATION_TYPES for f in self.formations),
            f"{key}.formations",
            f"must be a non-empty list of {list(FORMATION_TYPES)}",
            self.formations,
        )
        require(
            len(self.drives) > 0 and all(d in DRIVE_KINDS for d in self.drives),
            f"{key}.drives",
            f"must be a non-empty list of {list(DRIVE_KINDS)}",
            self.drives,
        )
        require(0.4 < self.spacing <= 3.0, f"{key}.spacing", "must be in (0.4, 3]", self.spacing)


@dataclass
class _Layout:
    """Where a family may put obstacles: x from x0 to x1, the world's height, the free lane's centre."""

    x0: float
    x1: float
    height: float
    centre: float


def _r(x: float, digits: int = 3) -> float:
    """A plain float rounded for the YAML file (numpy floats do not serialise)."""
    return round(float(x), digits)


def _box(x0: float, x1: float, y0: float, y1: float) -> dict:
    return {"box": {"center": [_r((x0 + x1) / 2, 3), _r((y0 + y1) / 2, 3)], "size": [_r(x1 - x0, 3), _r(y1 - y0, 3)]}}


def _walls_around(x0: float, x1: float, y_lo: float, y_hi: float, height: float) -> list[dict]:
    """Two boxes leaving a free lane y_lo..y_hi between x0 and x1."""
    out = []
    if y_lo > 0.05:
        out.append(_box(x0, x1, 0.0, y_lo))
    if y_hi < height - 0.05:
        out.append(_box(x0, x1, y_hi, height))
    return out


def _lane(rng: np.random.Generator, lay: _Layout, width: float, offset: float) -> tuple[float, float]:
    """A lane of `width` centred at most `offset` from the layout's centre, inside the world with 0.3 m to spare."""
    c = lay.centre + rng.uniform(-offset, offset)
    c = float(np.clip(c, width / 2 + 0.3, lay.height - width / 2 - 0.3))
    return c - width / 2, c + width / 2


def _corridor(rng, cfg: MapsConfig, lay: _Layout, long: bool = False) -> list[dict]:
    w = rng.uniform(*cfg.width)
    lo, hi = cfg.length if not long else (max(cfg.length[0], 6.0), max(cfg.length[1], 6.0))
    length = min(rng.uniform(lo, hi), lay.x1 - lay.x0)
    x0 = rng.uniform(lay.x0, max(lay.x0, lay.x1 - length))  # max: the length may fill the stretch to the last ulp
    y_lo, y_hi = _lane(rng, lay, w, 1.0)
    return _walls_around(x0, x0 + length, y_lo, y_hi, lay.height)


def _doorway(rng, cfg: MapsConfig, lay: _Layout) -> list[dict]:
    w = rng.uniform(*cfg.width)
    thick = rng.uniform(0.2, 0.5)
    x0 = rng.uniform(lay.x0, lay.x1 - thick)
    centred = rng.random() < 0.5
    y_lo, y_hi = _lane(rng, lay, w, 0.0 if centred else lay.height / 2 - w / 2 - 0.5)
    return _walls_around(x0, x0 + thick, y_lo, y_hi, lay.height)


def _bend(rng, cfg: MapsConfig, lay: _Layout, s_shape: bool) -> list[dict]:
    """A lane that shifts sideways (a dog-leg), or shifts and comes back (an S-bend), built from wall blocks."""
    w = rng.uniform(*cfg.width)
    shift = rng.uniform(1.0, 3.0) * rng.choice([-1.0, 1.0])
    pieces = 3 if s_shape else 2
    seg = min(rng.uniform(1.5, 4.0), (lay.x1 - lay.x0) / pieces)
    x = rng.uniform(lay.x0, max(lay.x0, lay.x1 - pieces * seg))  # max: seg may fill the stretch to the last ulp
    centres = [lay.centre, lay.centre + shift, lay.centre][:pieces]
    out: list[dict] = []
    for k, c in enumerate(centres):
        c = float(np.clip(c, w / 2 + 0.3, lay.height - w / 2 - 0.3))
        out += _walls_around(x + k * seg, x + (k + 1) * seg, c - w / 2, c + w / 2, lay.height)
    return out


def _gaps(rng, cfg: MapsConfig, lay: _Layout) -> list[dict]:
    """A wall across the way with 2 or 3 gaps (several passages lead to the goal)."""
    k = int(rng.integers(2, 4))
    w = rng.uniform(cfg.width[0], min(cfg.width[1], (lay.height - 0.6) / k - 0.6))
    thick = rng.uniform(0.3, 3.0)
    x0 = rng.uniform(lay.x0, lay.x1 - thick)
    centres = (np.arange(k) + 0.5) * lay.height / k + rng.uniform(-0.3, 0.3, k)
    edges = [0.0]
    for c in centres:
        edges += [c - w / 2, c + w / 2]
    edges.append(lay.height)
    return [
        _box(x0, x0 + thick, edges[2 * i], edges[2 * i + 1])
        for i in range(k + 1)
        if edges[2 * i + 1] - edges[2 * i] > 0.05
    ]


def _bollards(rng, cfg: MapsConfig, lay: _Layout) -> list[dict]:
    """One or two rows of bollards across the way; gaps between surfaces from the low end of the width range."""
    r = rng.uniform(0.1, 0.25)
    gap = rng.uniform(cfg.width[0], min(cfg.width[1], 1.8))
    pitch = gap + 2 * r
    out = []
    rows = int(rng.integers(1, 3))
    x = rng.uniform(lay.x0, lay.x1 - 2.0)
    for row in range(rows):
        phase = rng.uniform(0, pitch)
        for y in np.arange(phase, lay.height, pitch):
            out.append({"circle": {"center": [_r(x + 2.0 * row, 3), _r(float(y), 3)], "radius": _r(r, 3)}})
    return out


def _field(rng, cfg: MapsConfig, lay: _Layout) -> list[dict]:
    """An obstacle field: discs and boxes with random gaps between them."""
    out: list[dict] = []
    placed: list[tuple[float, float, float]] = []
    for _ in range(int(rng.integers(8, 25))):
        for _try in range(20):
            size = rng.uniform(0.15, 0.7)
            c = (rng.uniform(lay.x0, lay.x1), rng.uniform(0.3, lay.height - 0.3))
            if all(math.dist(c, p[:2]) > size + p[2] + cfg.width[0] for p in placed):
                placed.append((*c, size))
                if rng.random() < 0.6:
                    out.append({"circle": {"center": [_r(c[0], 3), _r(c[1], 3)], "radius": _r(size, 3)}})
                else:
                    s = _r(size * math.sqrt(2), 3)
                    out.append(
                        {
                            "box": {
                                "center": [_r(c[0], 3), _r(c[1], 3)],
                                "size": [s, s],
                                "angle_deg": round(float(rng.uniform(0, 90)), 1),
                            }
                        }
                    )
                break
    return out


BUILDERS: dict[str, Callable[..., list[dict]]] = {
    "corridor": _corridor,
    "bridge": lambda rng, cfg, lay: _corridor(rng, cfg, lay, long=True),
    "doorway": _doorway,
    "bend": lambda rng, cfg, lay: _bend(rng, cfg, lay, s_shape=False),
    "s_bend": lambda rng, cfg, lay: _bend(rng, cfg, lay, s_shape=True),
    "gaps": _gaps,
    "bollards": _bollards,
    "field": _field,
}


def _extent(kind: str, n: int, spacing: float) -> tuple[float, float]:
    slots = formation_slots(kind, n, spacing, 90.0)
    return float(np.ptp(slots[:, 0])), float(np.ptp(slots[:, 1]))


def draw_map(rng: np.random.Generator, cfg: MapsConfig, name: str) -> ScenarioConfig:
    """One random map with its team; raises nothing: a map without a route is redrawn (at most 50 times)."""
    from stafpipe.geometry import Geometry

    for _ in range(50):
        family = str(rng.choice(cfg.families))
        n = int(rng.integers(cfg.team_sizes[0], cfg.team_sizes[1] + 1))
        kind = str(rng.choice(cfg.formations))
        drive = str(rng.choice(cfg.drives))
        depth, width = _extent(kind, n, cfg.spacing)
        height = round(max(10.0, width + 4.0) + rng.uniform(0.0, 3.0), 2)
        middle = rng.uniform(8.0, 18.0)  # the stretch where the obstacles lie
        start_x = 1.5 + depth / 2  # the formation's back 1.5 m from the world's wall
        x0 = start_x + depth / 2 + 2.0  # 2 m of free space between the formation and the obstacles
        length = _r(2 * x0 + middle, 2)
        lay = _Layout(x0, length - x0, height, height / 2)
        obstacles = BUILDERS[family](rng, cfg, lay)
        start = [_r(start_x, 3), _r(height / 2, 3)]
        goal = [_r(length - start_x, 3), _r(height / 2 + rng.uniform(-1.0, 1.0), 3)]
        spec = ScenarioConfig(
            name=name,
            world=WorldBounds(0.0, 0.0, length, height),
            obstacles=obstacles,
            team=TeamSpec(n=n, formation=kind, spacing=cfg.spacing, start=start, goal=goal, heading_deg=0.0),
            robot=RobotSpec(drive=drive),
            time_limit=_r(3.0 * length + 60.0, 1),
        )
        scenario = build_scenario(spec)
        try:
            route = Geometry(scenario).shortest_path(
                (start[0], start[1]), (goal[0], goal[1]), scenario.spec.robot.radius + 0.05
            )
        except ValueError:
            continue
        if len(route) >= 2:
            spec.name = f"{name}-{family}"
            return turned(spec, int(rng.integers(4))) if cfg.turns else spec
    raise RuntimeError(f"maps: no passable map in 50 draws (families {cfg.families}, width {cfg.width})")


def turned(spec: ScenarioConfig, quarters: int) -> ScenarioConfig:
    """`spec` turned anticlockwise by `quarters` quarter turns about the origin and moved back so that its world
    starts at (0, 0): a point (x, y) goes to (-y, x) per quarter turn; boxes and the team's heading turn with it."""
    w = spec.world
    corners = np.array([[w.xmin, w.ymin], [w.xmax, w.ymax]])
    turn = np.linalg.matrix_power(np.array([[0.0, -1.0], [1.0, 0.0]]), quarters % 4)  # exact, unlike cos and sin
    low, high = (corners @ turn.T).min(axis=0), (corners @ turn.T).max(axis=0)

    def point(p) -> list[float]:
        q = np.asarray(p, float) @ turn.T - low
        return [_r(q[0], 3), _r(q[1], 3)]

    obstacles = []
    for ob in spec.obstacles:
        if "box" in ob:
            box = dict(ob["box"], center=point(ob["box"]["center"]))
            box["angle_deg"] = _r(float(box.get("angle_deg", 0.0)) + 90.0 * quarters, 1)
            obstacles.append({"box": box})
        else:  # the generator's other obstacles are discs
            obstacles.append({"circle": dict(ob["circle"], center=point(ob["circle"]["center"]))})
    team = replace(
        spec.team,
        start=point(spec.team.start),
        goal=point(spec.team.goal),
        heading_deg=_r(spec.team.heading_deg + 90.0 * quarters, 1),
    )
    world = WorldBounds(0.0, 0.0, _r(high[0] - low[0], 3), _r(high[1] - low[1], 3))
    return replace(spec, world=world, obstacles=obstacles, team=team)


def generate_maps(cfg: MapsConfig, seed: int, prefix: str = "gen") -> list[ScenarioConfig]:
    """`cfg.count` maps; map k depends only on (seed, k), so a longer run extends a shorter one."""
    cfg.check()
    return [draw_map(np.random.default_rng([seed, k]), cfg, f"{prefix}{seed}_{k:04d}") for k in range(cfg.count)]
