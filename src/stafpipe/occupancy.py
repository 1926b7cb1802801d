"""Static obstacles from a ROS occupancy map (the `map_server` format: a YAML file naming a PGM or PNG image).

A scenario's `occupancy.map` names the map's YAML (docs/scenarios.md). Its fields, as `map_server` reads them:
`image` (path relative to the YAML), `resolution` (m per cell), `origin` ([x, y, yaw] of the lower-left pixel),
`occupied_thresh`, `free_thresh`, `negate`; `mode` trinary (default) or scale. A cell is occupied when its occupancy
p = (255 - value) / 255 (value / 255 with `negate: 1`) exceeds `occupied_thresh`, free below `free_thresh`, unknown
between: unknown cells count as occupied unless the scenario says `occupancy.unknown: free`.

The occupied cells become polygons (shapely: the union of the cells, simplified by at most `occupancy.simplify`
metres, one cell by default), whose rings become the scenario's wall segments; the raster itself answers "is this
point inside an obstacle" (planning grid, start and goal checks), so walls of any thickness and rooms (holes) need no
polygon decomposition.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from stafpipe.errors import StafpipeError, yaml_problem

IMAGE_SUFFIXES = (".pgm", ".png")


class MapError(StafpipeError):
    """A ROS map file that is missing or malformed; the message names the file and the field."""


@dataclass
class OccupancyGrid:
    """Occupied cells of a map (row 0 at the bottom: y grows with the row) and where they lie in the world."""

    occupied: np.ndarray
    """(H, W) bool."""
    resolution: float
    origin: tuple[float, float, float]
    """x, y of the lower-left corner of cell (0, 0) and the map's yaw (rad)."""
    source: str
    _segments: dict[float, list] = field(default_factory=dict, repr=False, compare=False)

    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the map's cells in the world."""
        h, w = self.occupied.shape
        corners = self.to_world(np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]) * self.resolution)
        return (*corners.min(axis=0), *corners.max(axis=0))

    def to_world(self, local: np.ndarray) -> np.ndarray:
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        return np.stack([ox + c * local[..., 0] - s * local[..., 1], oy + s * local[..., 0] + c * local[..., 1]], -1)

    def _cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row and column (P,) of the cell under each point, and whether it is on the map."""
        ox, oy, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = points[:, 0] - ox, points[:, 1] - oy
        col = np.floor((c * dx + s * dy) / self.resolution).astype(int)
        row = np.floor((-s * dx + c * dy) / self.resolution).astype(int)
        h, w = self.occupied.shape
        return row, col, (row >= 0) & (row < h) & (col >= 0) & (col < w)

    def covers(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: the point lies on one of the map's cells."""
        return self._cells(points)[2]

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(P,) bool: the point lies in an occupied cell (points off the map: False)."""
        row, col, inside = self._cells(points)
        out = np.zeros(len(points), dtype=bool)
        out[inside] = self.occupied[row[inside], col[inside]]
        return out

    def wall_segments(self, simplify: float) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """Every edge of the simplified outline of the occupied region (outer rings and holes), in world metres."""
        if simplify not in self._segments:
            self._segments[simplify] = self._outline(simplify)
        return self._segments[simplify]

    def _outline(self, simplify: float) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        import shapely

        rows, starts, ends = _runs(self.occupied)
        cells = shapely.box(starts, rows, ends, rows + 1)  # one box per horizontal run of occupied cells
        region = shapely.union_all(cells).simplify(simplify / self.resolution, preserve_topology=True)
        segments = []
        for poly in getattr(region, "geoms", [region]):
            if poly.is_empty:
                continue
            for ring in [poly.exterior, *poly.interiors]:
                xy = self.to_world(np.asarray(ring.coords) * self.resolution)
                segments += [
                    ((float(xy[k, 0]), float(xy[k, 1])), (float(xy[k + 1, 0]), float(xy[k + 1, 1])))
                    for k in range(len(xy) - 1)
                ]
        return segments


MIN_RESOLUTION = 0.005
"""m per cell: a wall one cell thick must be thicker than the overlap the physics lets a contact have
(`world.collision_slop`, 5 mm), or a robot pressed against it can come out on its other side; finer maps are
downsampled first (map_server maps are usually 2.5-10 cm)."""
MAX_MAP_PIXELS = 50_000_000
"""Pixels a map image may have (a 7,000 x 7,000 map: 350 m square at 5 cm); Pillow's own guard is a warning up to
178 million and an exception name beyond."""


def _runs(occupied: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row, first column and one-past-last column of every horizontal run of True cells."""
    padded = np.zeros((occupied.shape[0], occupied.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = occupied
    step = np.diff(padded, axis=1)
    r0, c0 = np.nonzero(step == 1)
    r1, c1 = np.nonzero(step == -1)  # row-major order pairs each start with its end
    assert np.array_equal(r0, r1)
    return r0.astype(float), c0.astype(float), c1.astype(float)


def _field(meta: dict[str, Any], key: str, where: str, default: Any = None) -> Any:
    if key not in meta:
        if default is None:
            raise MapError(f"{where}: misses the field {key!r}")
        return default
    return meta[key]


def _number(value: Any, where: str, low: float, high: float = math.inf, low_open: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < low or value > high or (low_open and value == low):
        bound = f"{'>' if low_open else '>='} {low}" + (f" and <= {high}" if high < math.inf else "")
        raise MapError(f"{where} must be a number {bound}, got {value!r}")
    return float(value)


class _UniqueKeys(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key written twice: plain `safe_load` keeps the last value without a word, so a
    map whose `resolution` is written twice would be read at the scale of whichever came last."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # `<<: *base`: the safe loader merges it below
                continue
            key = self.construct_object(key_node, deep=deep)
            try:
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"found duplicate key {key}", key_node.start_mark
                    )
                seen.add(key)
            except TypeError:  # an unhashable key: the safe loader refuses it with its own message
                continue
        return super().construct_mapping(node, deep)


def load_map(path: str | Path, unknown: str = "occupied") -> OccupancyGrid:
    """Read a `map_server` map YAML and its image; every error names the file and the field."""
    path = Path(path)
    if path.is_dir():
        raise MapError(f"occupancy.map: {path} is a directory; name the map's YAML file in it")
    if not path.is_file():
        raise MapError(f"occupancy.map: map file {path} does not exist")
    try:
        meta = yaml.load(path.read_text(), Loader=_UniqueKeys)
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise MapError(f"map file {path}: not valid YAML ({yaml_problem(exc)})") from None
    if not isinstance(meta, dict):
        raise MapError(f"map file {path}: must be a mapping with image, resolution, origin, got {meta!r}")
    where = f"map file {path}"
    image = _field(meta, "image", where)
    if not isinstance(image, str) or Path(image).suffix.lower() not in IMAGE_SUFFIXES:
        raise MapError(f"{where}: image must name a {' or '.join(IMAGE_SUFFIXES)} file, got {image!r}")
    image_path = path.parent / image
    if not image_path.is_file():
        raise MapError(f"{where}: image {image_path} does not exist")
    resolution = _number(_field(meta, "resolution", where), f"{where}: resolution", 0.0, low_open=True)
    if resolution < MIN_RESOLUTION:
        raise MapError(
            f"{where}: resolution {resolution:g} m per cell is below {MIN_RESOLUTION:g}: a wall one cell thick would "
            "be thinner than the overlap the physics allows a contact; downsample the image (and raise the resolution)"
        )
    origin = _field(meta, "origin", where)
    if not isinstance(origin, list) or len(origin) not in (2, 3):
        raise MapError(f"{where}: origin must be [x, y, yaw], got {origin!r}")
    ox, oy, *yaw = (_number(v, f"{where}: origin[{k}]", -math.inf) for k, v in enumerate(origin))
    occupied_thresh = _number(_field(meta, "occupied_thresh", where, 0.65), f"{where}: occupied_thresh", 0.0, 1.0)
    free_thresh = _number(_field(meta, "free_thresh", where, 0.25), f"{where}: free_thresh", 0.0, 1.0)
    if free_thresh > occupied_thresh:
        raise MapError(f"{where}: free_thresh ({free_thresh}) must not exceed occupied_thresh ({occupied_thresh})")
    negate = _field(meta, "negate", where, 0)
    if negate not in (0, 1, True, False):
        raise MapError(f"{where}: negate must be 0 or 1, got {negate!r}")
    mode = _field(meta, "mode", where, "trinary")
    if mode not in ("trinary", "scale"):
        raise MapError(f"{where}: mode must be trinary or scale (raw maps are not supported), got {mode!r}")
    if unknown not in ("occupied", "free"):
        raise MapError(f"occupancy.unknown must be occupied or free, got {unknown!r}")
    stat = image_path.stat()
    return _grid(
        str(image_path),
        (stat.st_mtime_ns, stat.st_size),
        bool(negate),
        occupied_thresh,
        free_thresh,
        unknown,
        resolution,
        (ox, oy, yaw[0] if yaw else 0.0),
        str(path),
    )


@functools.lru_cache(maxsize=16)
def _grid(
    image_path: str,
    version: tuple[int, int],
    negate: bool,
    occupied_thresh: float,
    free_thresh: float,
    unknown: str,
    resolution: float,
    origin: tuple[float, float, float],
    source: str,
) -> OccupancyGrid:
    """The cells of an image, read once per version of the file: a scenario is built several times per run (with
    each formation, each eval), and the image and its outline need not be read and united each time."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(image_path) as img:
            if img.width * img.height > MAX_MAP_PIXELS:  # read from the header, before any pixel is decoded
                raise MapError(
                    f"map file {source}: image {image_path} is {img.width} x {img.height} pixels, more than "
                    f"{MAX_MAP_PIXELS:,}; downsample it (and raise `resolution` by the same factor)"
                )
            gray = np.asarray(img.convert("L"), dtype=float)
    except Image.DecompressionBombError:
        raise MapError(
            f"map file {source}: image {image_path} declares more than {MAX_MAP_PIXELS:,} pixels; downsample it"
        ) from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError) as exc:  # Pillow: a malformed header
        raise MapError(f"map file {source}: image {image_path} cannot be read ({exc})") from None
    p = gray / 255.0 if negate else (255.0 - gray) / 255.0
    occupied = p > occupied_thresh
    if unknown == "occupied":
        occupied |= p >= free_thresh  # neither free nor occupied: unknown
    cells = occupied[::-1].copy()
    cells.flags.writeable = False  # shared by every scenario built from this map
    return OccupancyGrid(cells, resolution, origin, source)
