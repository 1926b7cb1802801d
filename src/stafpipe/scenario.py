"""Scenarios: validated data from YAML (docs/scenarios.md), built in (conf/scenario/) or given by path.

A scenario holds the world bounds (walls), static obstacles, optional moving obstacles, the team (size, formation,
start and goal centres, heading), the robot, and a time limit. `load_scenario` checks every field and names the bad one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from stafpipe.distances import distance_to
from stafpipe.errors import StafpipeError, yaml_problem
from stafpipe.formations import FORMATION_TYPES, formation_slots, place
from stafpipe.occupancy import OccupancyGrid, load_map
from stafpipe.sections import section

DRIVES = ("holonomic", "diff_drive")


class ScenarioError(StafpipeError):
    """A scenario file or config is malformed; the message names the field."""


@dataclass
class WorldBounds:
    """The rectangle the robots live in; its sides are walls."""

    xmin: float = 0.0
    ymin: float = 0.0
    xmax: float = 30.0
    ymax: float = 12.0


@dataclass
class TeamSpec:
    """The team: size, formation template, start and goal formation centres, facing direction."""

    n: int = 10
    formation: str = "circle"
    spacing: float = 1.0
    angle_deg: float = 90.0
    start: list[float] = field(default_factory=lambda: [4.0, 6.0])
    goal: list[float] = field(default_factory=lambda: [26.0, 6.0])
    heading_deg: float = 0.0


@dataclass
class RobotSpec:
    """A disc robot (STAF Gazebo robots are holonomic; Warthog and Limo are differential drive, STAF Section 4)."""

    radius: float = 0.2
    max_speed: float = 1.0
    max_accel: float = 2.0
    drive: str = "holonomic"
    max_turn_rate: float = 2.0
    """Differential drive only: the largest angular velocity, rad/s."""


@dataclass
class MovingObstacle:
    """A disc moving along waypoints at constant speed (Zhu et al. 2019, Scenario 1: a walking human)."""

    radius: float = 0.3
    speed: float = 0.5
    waypoints: list[Any] = field(default_factory=list)
    loop: bool = True


@dataclass
class OccupancySpec:
    """Static obstacles from a ROS `map_server` map (occupancy.py, docs/scenarios.md), added to `obstacles`."""

    map: str = ""
    """The map's YAML file; a relative path is relative to the scenario file (for a built-in scenario composed by
    Hydra, to conf/scenario/). Empty: no map."""
    unknown: str = "occupied"
    """What cells of unknown occupancy are: `occupied` (safe) or `free`."""
    simplify: float = 0.0
    """How far (m) the simplified wall outline may stray from the cells' edges; 0: one cell."""


@dataclass
class ScenarioConfig:
    """A scenario (group `scenario`): inline fields, or `path` to a scenario YAML file that replaces them."""

    name: str = "corridor"
    path: str | None = None
    world: WorldBounds = field(default_factory=WorldBounds)
    obstacles: list[Any] = field(default_factory=list)
    occupancy: OccupancySpec = field(default_factory=OccupancySpec)
    moving_obstacles: list[MovingObstacle] = field(default_factory=list)
    reference_path: list[Any] = field(default_factory=list)
    """Optional waypoints for the formation centre (a leader's trajectory, Zhu's circular reference)."""
    team: TeamSpec = field(default_factory=TeamSpec)
    robot: RobotSpec = field(default_factory=RobotSpec)
    time_limit: float = 200.0
    """Seconds before an episode is cut off."""


@dataclass(frozen=True)
class Capsule:
    """A static obstacle piece: the set of points within `radius` of segment a-b (a == b is a disc)."""

    a: tuple[float, float]
    b: tuple[float, float]
    radius: float


@dataclass
class Scenario:
    """A validated scenario with its obstacles in geometric form."""

    spec: ScenarioConfig
    polygons: list[np.ndarray]
    """Solid convex-or-not polygons (boxes included), each (k, 2), counter-clockwise."""
    capsules: list[Capsule]
    """Every static obstacle boundary as capsules: polygon edges (radius 0), circles, segments, world walls."""
    occupancy: OccupancyGrid | None = None
    """The occupied cells of `occupancy.map`, if any (its outline is among the capsules)."""

    @property
    def name(self) -> str:
        return self.spec.name

    def template(self) -> np.ndarray:
        """The team's formation slots (n, 2) in the formation frame."""
        t = self.spec.team
        return formation_slots(t.formation, t.n, t.spacing, t.angle_deg)


def _vec2(value: Any, where: str) -> tuple[float, float]:
    """`value` as a point [x, y]; anything else (a number, a flat list of points, a word) named at `where`."""
    if OmegaConf.is_config(value):
        value = OmegaConf.to_container(value)
    ok = isinstance(value, list | tuple) and len(value) == 2 and all(isinstance(v, int | float) for v in value)
    if not ok or not all(math.isfinite(v) for v in value):
        raise ScenarioError(f"{where} must be two numbers [x, y], got {value!r}")
    return float(value[0]), float(value[1])


MAX_TIME_LIMIT = 3600.0
"""s: the longest episode a scenario may ask for (the longest shipped one is 600 s); longer is a typo or a hang."""
BOUNDS = {
    "robot.radius": 5.0,
    "robot.max_speed": 50.0,
    "robot.max_accel": 500.0,
    "robot.max_turn_rate": 100.0,
    "team.spacing": 100.0,
    "world extent": 10_000.0,
    "moving_obstacles radius": 50.0,
    "moving_obstacles speed": 50.0,
}
"""Upper bounds (m, m/s, m/s^2, rad/s) grounded in the robots these papers use (0.1-1 m, 0.5-2 m/s) with a wide
margin: a value beyond one is a typo that would make every metric meaningless (a 1e308 m/s robot's TT / bound was
3.6e307); a world side above 10 km is past any map the physics' float precision serves at cm scale."""
MAX_TEAM = 1000
"""Robots in a team: the largest team any benchmark runs (STAF's decision time at 1,000 robots)."""


def _at_most(value: float, bound: str, where: str = "") -> float:
    """`value` if it is within `BOUNDS[bound]`, else an error naming `where` (default: the bound's own name)."""
    if value > BOUNDS[bound]:
        raise ScenarioError(f"{where or bound} must be at most {BOUNDS[bound]:g}, got {value!r}")
    return value


def _number(value: Any, where: str) -> float:
    """`value` as a finite number (an angle, say), else an error naming `where`."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _positive(value: Any, where: str) -> float:
    if not isinstance(value, int | float) or not value > 0 or not math.isfinite(value):
        raise ScenarioError(f"{where} must be a positive number, got {value!r}")
    return float(value)


def _obstacle(item: Any, where: str) -> tuple[np.ndarray | None, list[Capsule]]:
    kinds = ("box", "polygon", "circle", "segment")
    if not isinstance(item, dict) or len(item) != 1 or next(iter(item)) not in kinds:
        raise ScenarioError(
            f"{where} must be one of {{box: ..}}, {{polygon: ..}}, {{circle: ..}}, {{segment: ..}}, got {item!r}"
        )
    kind, body = next(iter(item.items()))
    where = f"{where}.{kind}"
    if kind == "box":
        _keys(body, {"center", "size"}, {"angle_deg"}, where)
        cx, cy = _vec2(body["center"], f"{where}.center")
        w, h = _vec2(body["size"], f"{where}.size")
        _positive(w, f"{where}.size[0]"), _positive(h, f"{where}.size[1]")
        a = math.radians(_number(body.get("angle_deg", 0.0), f"{where}.angle_deg"))
        corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2.0
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        poly = corners @ rot.T + (cx, cy)
    elif kind == "polygon":
        if not isinstance(body, list) or len(body) < 3:
            raise ScenarioError(f"{where} must be a list of at least 3 points, got {body!r}")
        poly = np.array([_vec2(p, f"{where}[{i}]") for i, p in enumerate(body)])
        area = 0.5 * float(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
        if abs(area) < 1e-9:
            raise ScenarioError(f"{where} has zero area")
        if area < 0:
            poly = poly[::-1]
    elif kind == "circle":
        _keys(body, {"center", "radius"}, set(), where)
        c = _vec2(body["center"], f"{where}.center")
        return None, [Capsule(c, c, _positive(body["radius"], f"{where}.radius"))]
    else:
        _keys(body, {"a", "b"}, {"radius"}, where)
        radius = _number(body.get("radius", 0.05), f"{where}.radius")
        if radius < 0:
            raise ScenarioError(f"{where}.radius must be >= 0, got {radius}")
        return None, [Capsule(_vec2(body["a"], f"{where}.a"), _vec2(body["b"], f"{where}.b"), radius)]
    edges = [Capsule(tuple(poly[i]), tuple(poly[(i + 1) % len(poly)]), 0.0) for i in range(len(poly))]
    return poly, edges


def _keys(body: Any, required: set[str], optional: set[str], where: str) -> None:
    if not isinstance(body, dict):
        raise ScenarioError(f"{where} must be a mapping, got {body!r}")
    missing, unknown = required - set(body), set(body) - required - optional
    if missing:
        raise ScenarioError(f"{where} misses {sorted(missing)}")
    if unknown:
        raise ScenarioError(f"{where} has unknown key(s) {sorted(unknown)}; allowed: {sorted(required | optional)}")


def _check(spec: ScenarioConfig) -> None:
    w = spec.world
    for key in ("xmin", "ymin", "xmax", "ymax"):
        _number(getattr(w, key), f"world.{key}")
    if not (w.xmax > w.xmin and w.ymax > w.ymin):
        raise ScenarioError(f"world must have xmax > xmin and ymax > ymin, got {w}")
    _at_most(max(w.xmax - w.xmin, w.ymax - w.ymin), "world extent", "the world's longer side")
    t, r = spec.team, spec.robot
    if t.n < 2:
        raise ScenarioError(f"team.n must be >= 2 (a formation needs two robots), got {t.n}")
    if t.n > MAX_TEAM:
        raise ScenarioError(f"team.n must be at most {MAX_TEAM}, got {t.n}")
    if t.formation not in FORMATION_TYPES:
        raise ScenarioError(f"team.formation must be one of {list(FORMATION_TYPES)}, got {t.formation!r}")
    _at_most(_positive(t.spacing, "team.spacing"), "team.spacing")
    _number(t.heading_deg, "team.heading_deg")
    if t.formation == "v" and not 0.0 < _number(t.angle_deg, "team.angle_deg") < 180.0:
        raise ScenarioError(f"team.angle_deg (the v formation's apex angle) must be in (0, 180), got {t.angle_deg!r}")
    for key in ("start", "goal"):
        x, y = _vec2(getattr(t, key), f"team.{key}")
        if not (w.xmin < x < w.xmax and w.ymin < y < w.ymax):
            raise ScenarioError(
                f"team.{key} {[x, y]} lies outside the world (x {w.xmin:g}..{w.xmax:g}, y {w.ymin:g}..{w.ymax:g})"
            )
    for key in ("radius", "max_speed", "max_accel", "max_turn_rate"):
        _at_most(_positive(getattr(r, key), f"robot.{key}"), f"robot.{key}")
    if math.dist(_vec2(t.start, "team.start"), _vec2(t.goal, "team.goal")) < 2 * r.radius:
        raise ScenarioError(
            f"team.goal {list(t.goal)} lies within a robot's diameter of team.start {list(t.start)}: there is no way "
            "to go (SR 1 and TT 0 would mean nothing)"
        )
    if r.drive not in DRIVES:
        raise ScenarioError(f"robot.drive must be one of {list(DRIVES)}, got {r.drive!r}")
    if t.spacing < 2 * r.radius:
        raise ScenarioError(f"team.spacing ({t.spacing}) must be at least the robot diameter ({2 * r.radius})")
    _positive(spec.time_limit, "time_limit")
    if spec.time_limit > MAX_TIME_LIMIT:
        raise ScenarioError(
            f"time_limit must be at most {MAX_TIME_LIMIT:g} s (an episode's log grows about 1.8 MB a second), "
            f"got {spec.time_limit!r}"
        )
    for j, p in enumerate(spec.reference_path):
        _vec2(p, f"reference_path[{j}]")
    if len(spec.reference_path) == 1:
        raise ScenarioError("reference_path has one point: a route needs at least two (or none: the shortest path)")
    for i, m in enumerate(spec.moving_obstacles):
        _at_most(
            _positive(m.radius, f"moving_obstacles[{i}].radius"),
            "moving_obstacles radius",
            f"moving_obstacles[{i}].radius",
        )
        _at_most(
            _positive(m.speed, f"moving_obstacles[{i}].speed"), "moving_obstacles speed", f"moving_obstacles[{i}].speed"
        )
        if len(m.waypoints) < 1:
            raise ScenarioError(f"moving_obstacles[{i}].waypoints needs at least one point")
        for j, p in enumerate(m.waypoints):
            _vec2(p, f"moving_obstacles[{i}].waypoints[{j}]")


def build_scenario(spec: ScenarioConfig) -> Scenario:
    """Validate `spec` and turn its obstacles into polygons and capsules."""
    _check(spec)
    polygons: list[np.ndarray] = []
    capsules: list[Capsule] = []
    for i, item in enumerate(spec.obstacles):
        poly, caps = _obstacle(OmegaConf.to_container(item) if OmegaConf.is_config(item) else item, f"obstacles[{i}]")
        if poly is not None:
            polygons.append(poly)
        capsules.extend(caps)
    grid = None
    if spec.occupancy.map:
        grid = _map_obstacles(spec, capsules)
    w = spec.world
    corners = [(w.xmin, w.ymin), (w.xmax, w.ymin), (w.xmax, w.ymax), (w.xmin, w.ymax)]
    capsules.extend(Capsule(corners[i], corners[(i + 1) % 4], 0.0) for i in range(4))
    scenario = Scenario(spec, polygons, capsules, grid)
    _check_placement(scenario)
    return scenario


def _check_placement(scenario: Scenario) -> None:
    """Every robot's slot at the start and at the goal (placed as World.reset places them) lies inside the world and
    clear of every obstacle: a team placed outside its world once ran with exit 0 and SR 1.0."""
    spec = scenario.spec
    t, r, w = spec.team, spec.robot.radius, spec.world
    unit = formation_slots(t.formation, t.n, t.spacing, t.angle_deg)
    for key in ("start", "goal"):
        slots = place(unit, np.array(getattr(t, key), dtype=float), math.radians(t.heading_deg))
        outside = (slots[:, 0] - r < w.xmin) | (slots[:, 0] + r > w.xmax)
        outside |= (slots[:, 1] - r < w.ymin) | (slots[:, 1] + r > w.ymax)
        if outside.any():
            k = int(np.argmax(outside))
            raise ScenarioError(
                f"team.{key}: robot {k}'s slot {np.round(slots[k], 2).tolist()} lies outside the world {w} "
                f"(team.n {t.n}, spacing {t.spacing}: the formation does not fit)"
            )
        clear = distance_to(slots, scenario.capsules, scenario.polygons, scenario.occupancy) - r
        if (clear < -1e-6).any():
            k = int(np.argmin(clear))
            raise ScenarioError(
                f"team.{key}: robot {k}'s slot {np.round(slots[k], 2).tolist()} overlaps an obstacle "
                f"({-clear[k]:.2f} m deep)"
            )
        if key == "start":
            for i, m in enumerate(spec.moving_obstacles):
                gap = np.linalg.norm(slots - np.asarray(m.waypoints[0], float), axis=1) - r - m.radius
                if (gap < 0).any():
                    k = int(np.argmin(gap))
                    raise ScenarioError(
                        f"moving_obstacles[{i}] starts on robot {k} of the team (waypoints[0] "
                        f"{list(m.waypoints[0])}, {-gap[k]:.2f} m deep): every episode would begin with a contact"
                    )


def _map_obstacles(spec: ScenarioConfig, capsules: list[Capsule]) -> OccupancyGrid:
    """Load `occupancy.map`, add its wall outline to `capsules`, refuse a team that starts or ends in a wall."""
    occ = spec.occupancy
    if occ.simplify < 0 or not math.isfinite(occ.simplify):
        raise ScenarioError(f"occupancy.simplify must be >= 0, got {occ.simplify}")
    grid = load_map(occ.map, occ.unknown)
    capsules.extend(Capsule(a, b, 0.0) for a, b in grid.wall_segments(occ.simplify or grid.resolution))
    t = spec.team
    for key in ("start", "goal"):
        centre = np.array(getattr(t, key), dtype=float)
        slots = np.zeros((0, 2))
        if t.n >= 2:  # the robots' slots, placed as World.reset places them
            slots = place(
                formation_slots(t.formation, t.n, t.spacing, t.angle_deg), centre, math.radians(t.heading_deg)
            )
        points = np.vstack([centre, slots])
        off = ~grid.covers(points)
        if off.any():
            who = "its centre" if off[0] else f"robot {int(np.argmax(off[1:]))}'s slot"
            x0, y0, x1, y1 = grid.extent()
            raise ScenarioError(
                f"team.{key} {centre.tolist()}: {who} lies off map {occ.map}, which covers x {x0:g}..{x1:g}, "
                f"y {y0:g}..{y1:g} ({grid.occupied.shape[1]} x {grid.occupied.shape[0]} cells of "
                f"{grid.resolution:g} m: is its resolution right?)"
            )
        hit = grid.contains(points)
        if hit.any():
            where = "its centre" if hit[0] else f"robot {int(np.argmax(hit[1:]))}'s slot"
            raise ScenarioError(f"team.{key} {centre.tolist()}: {where} lies in an occupied cell of map {occ.map}")
    return grid


def anchor_map(spec: ScenarioConfig, base: Path) -> None:
    """Make a relative `occupancy.map` relative to `base` (the scenario file's directory)."""
    if spec.occupancy.map and not Path(spec.occupancy.map).is_absolute():
        spec.occupancy.map = str(base / spec.occupancy.map)


def _required_sections(raw: Any, path: Path) -> None:
    """A scenario file says where its team starts and ends and how big its world is: nothing of it is taken from the
    default corridor (an empty file or one without `team:` once ran as an obstacle-free corridor, exit 0)."""
    if not isinstance(raw, DictConfig) or len(raw) == 0:
        raise ScenarioError(
            f"scenario file {path} is empty or not a mapping: it needs at least `world` (or "
            "`occupancy.map`) and `team` with `start` and `goal` (docs/scenarios.md)"
        )
    occupancy = raw.get("occupancy")
    if "world" not in raw and not (isinstance(occupancy, DictConfig) and occupancy.get("map")):
        raise ScenarioError(
            f"scenario file {path} misses `world` (xmin, ymin, xmax, ymax) and has no `occupancy.map` to take it from"
        )
    team = raw.get("team")
    missing = [k for k in ("start", "goal") if not isinstance(team, DictConfig) or k not in team]
    if missing:
        raise ScenarioError(
            f"scenario file {path} misses `team.{missing[0]}`: a scenario names where its team starts "
            "and where it goes (team.start, team.goal)"
        )


MAX_YAML_VALUES = 1_000_000
"""Values a scenario file may expand to once its YAML aliases are followed (the largest shipped map: a few thousand)."""


def _refuse_alias_bombs(path: Path) -> None:
    """Refuse a file whose aliases expand past `MAX_YAML_VALUES` (nested aliases double at every level: a file of a
    few lines can expand to billions), counted on the composed node graph, where an alias is one shared node, before
    anything is expanded."""
    try:
        root = yaml.compose(path.read_text(encoding="utf-8", errors="replace"), Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return  # a syntax error: OmegaConf.load says where
    sizes: dict[int, int] = {}

    def size(node: yaml.Node) -> int:
        if id(node) not in sizes:
            sizes[id(node)] = 0  # a recursive alias counts once (YAML's loader refuses it later)
            if isinstance(node, yaml.MappingNode):
                total = sum(size(k) + size(v) for k, v in node.value)
            elif isinstance(node, yaml.SequenceNode):
                total = sum(size(v) for v in node.value)
            else:
                total = 0
            sizes[id(node)] = min(1 + total, MAX_YAML_VALUES + 1)
        return sizes[id(node)]

    if root is not None and size(root) > MAX_YAML_VALUES:
        raise ScenarioError(
            f"scenario file {path} expands to more than {MAX_YAML_VALUES:,} values through its YAML aliases (&, *); "
            "write the values out, or split the scenario"
        )


def load_scenario_file(path: str | Path) -> ScenarioConfig:
    """Read a scenario YAML file into a typed ScenarioConfig; errors name the file and the field."""
    path = Path(path)
    if path.is_dir():  # a generate-maps output folder, say: a scenario is one file
        raise ScenarioError(
            f"scenario file {path} is a directory; name one scenario YAML in it (e.g. {path / 'map_0000.yaml'}), "
            f"or evaluate every map in it as a sweep: stafpipe eval -m scenario.path={path}"
        )
    if not path.is_file():
        raise ScenarioError(f"scenario file {path} does not exist")
    _refuse_alias_bombs(path)
    try:
        raw = OmegaConf.load(path)
    except Exception as exc:  # noqa: BLE001 - a YAML syntax error
        raise ScenarioError(f"scenario file {path}: not valid YAML ({yaml_problem(exc)})") from None
    _required_sections(raw, path)
    try:
        merged = OmegaConf.merge(OmegaConf.structured(ScenarioConfig), raw)
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None)
        raise ScenarioError(f"scenario file {path}: bad field {key!r}: {str(exc).splitlines()[0]}") from None
    spec = section(merged, ScenarioConfig)
    spec.path = None
    anchor_map(spec, path.parent)
    if spec.occupancy.map and "world" not in raw:  # the map's extent is the world
        try:
            xmin, ymin, xmax, ymax = load_map(spec.occupancy.map, spec.occupancy.unknown).extent()
        except StafpipeError as exc:
            raise ScenarioError(f"scenario file {path}: {exc}") from None
        spec.world = WorldBounds(float(xmin), float(ymin), float(xmax), float(ymax))
    return spec


def resolve_scenario(cfg: Any) -> Scenario:
    """The scenario of a `scenario` config node: its inline fields, or the file at `scenario.path`."""
    if cfg.get("path"):
        spec = load_scenario_file(cfg.path)
    else:
        try:
            spec = section(cfg, ScenarioConfig)
        except OmegaConfBaseException as exc:
            raise ScenarioError(f"scenario: {str(exc).splitlines()[0]}") from None
        if spec.occupancy.map and not Path(spec.occupancy.map).exists():
            from stafpipe.paths import conf_dir

            anchor_map(spec, conf_dir() / "scenario")  # a built-in scenario's map lies beside it
    try:
        return build_scenario(spec)
    except ScenarioError as exc:
        where = f"scenario file {cfg.path}" if cfg.get("path") else f"scenario '{spec.name}'"
        raise ScenarioError(f"{where}: {exc}") from None
