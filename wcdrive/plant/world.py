"""The static world the chair drives in: walls (segments), boxes and round posts in the
map frame, hand-written or from a ROS map (``wcdrive.plant.rosmap``), and the exact
ray cast a 2D lidar needs.

    world = World.from_table({"walls": [[0, 0, 10, 0, 10, 5]], "circles": [[4, 2, 0.05]]})
    world = World.from_grid(load_map("room.yaml"))     # the occupied cells' outlines
    world.cast(origins, angles, max_range=40.0)         # metres to the first hit, inf for none
    world.cast_exact(origins, angles, max_range=40.0)   # the same with numpy: the reference

A hand-written world (a scenario's ``[world]`` table, or a TOML file of its own):

- ``walls``: polylines, each a flat list ``[x0, y0, x1, y1, ...]`` (two points or more);
- ``boxes``: ``[cx, cy, width, height]`` or ``[cx, cy, width, height, yaw_deg]``;
- ``circles``: ``[x, y, radius]`` (table legs, posts);
- ``map``: a map_server YAML, its path relative to ``base``; its occupied cells join
  the rest.

Everything is a segment but the circles: a box is its four sides, an occupied region
of a map its outline (the edges between an occupied cell and one that is not, merged
where they run on in a line). The ray cast is exact for that geometry (a ray's length
to a wall is the distance along it to the first segment or circle it meets), in
float64. ``cast_exact`` casts all rays at once with numpy, every ray against every
item: the reference. ``cast`` gives the same figures bit for bit through a grid of
cells built on the first cast, in C (``wcdrive.plant.raycast``, which says where the
reference's own figures are rounding noise), and is ``cast_exact`` where the C helper
cannot be had. A world's geometry is fixed: its arrays are not to be changed after its
first cast.
"""

from __future__ import annotations

import functools
import itertools
import math
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wcdrive.errors import WcdriveFileError
from wcdrive.plant.raycast import RayGrid
from wcdrive.plant.rosmap import OCCUPIED, MapFileError, OccupancyGrid, load_map

#: The worlds that come with wcdrive (the scenarios' ``worlds`` folder): a hospital
#: corridor (a map_server map) and a furnished room (hand-written).
BUNDLED_WORLDS = Path(__file__).resolve().parents[1] / "sim" / "scenarios" / "worlds"


class WorldError(WcdriveFileError):
    """A world table that cannot be built (the message says which entry and why)."""


def _polyline(points: Iterable[float], what: str) -> list[tuple[float, float, float, float]]:
    flat = [float(v) for v in points]
    if len(flat) < 4 or len(flat) % 2:
        raise WorldError(f"{what}: a polyline needs x, y pairs, two points at least; got {len(flat)} numbers")
    pts = list(zip(flat[0::2], flat[1::2], strict=True))
    return [(a[0], a[1], b[0], b[1]) for a, b in itertools.pairwise(pts) if a != b]


def box_segments(cx: float, cy: float, width: float, height: float, yaw: float = 0.0
                 ) -> list[tuple[float, float, float, float]]:
    """The four sides of a box centred at (cx, cy), turned by ``yaw`` radians."""
    if not (width > 0 and height > 0):
        raise WorldError(f"a box needs a positive width and height, not {width} x {height}")
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(cx + c * u - s * v, cy + s * u + c * v)
               for u, v in ((-width / 2, -height / 2), (width / 2, -height / 2),
                            (width / 2, height / 2), (-width / 2, height / 2))]
    return [(*corners[i], *corners[(i + 1) % 4]) for i in range(4)]


def grid_outline(grid: OccupancyGrid) -> np.ndarray:
    """(N, 4) segments ``x0, y0, x1, y1`` in the map frame: the edges between an
    occupied cell and a cell that is not (or the map's border), collinear neighbours
    merged into one segment."""
    occ = np.pad(grid.data == OCCUPIED, 1, constant_values=False)
    runs: list[tuple[float, float, float, float]] = []    # in cell units, before the origin
    # horizontal edges: between row r-1 and row r (padded indices), where one side is occupied
    below, above = occ[:-1, 1:-1], occ[1:, 1:-1]
    for edges, offset in ((below & ~above, 0), (above & ~below, 0)):
        for r, row in enumerate(edges):
            runs += [(c0, r + offset, c1, r + offset) for c0, c1 in _runs(row)]
    left, right = occ[1:-1, :-1], occ[1:-1, 1:]
    for edges in (left & ~right, right & ~left):
        for c, col in enumerate(edges.T):
            runs += [(c, r0, c, r1) for r0, r1 in _runs(col)]
    if not runs:
        return np.zeros((0, 4))
    cells = np.asarray(runs, dtype=float) * grid.resolution
    x0, y0, yaw = grid.origin
    cos, sin = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(cells)
    for k in (0, 2):
        u, v = cells[:, k], cells[:, k + 1]
        out[:, k], out[:, k + 1] = x0 + cos * u - sin * v, y0 + sin * u + cos * v
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) of each run of True in a 1-D mask, end exclusive."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    change = np.flatnonzero(np.diff(padded))
    return list(zip(change[0::2].tolist(), change[1::2].tolist(), strict=True))


@dataclass(frozen=True, eq=False)
class World:
    """Static geometry in the map frame: ``segments`` (N, 4) ``x0, y0, x1, y1`` and
    ``circles`` (M, 3) ``x, y, r``, in metres; ``grid`` the ROS map it came from, if
    any (for ``/map``)."""

    segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    circles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    grid: OccupancyGrid | None = None

    @classmethod
    def from_grid(cls, grid: OccupancyGrid) -> World:
        """The outline of a map's occupied cells."""
        return cls(grid_outline(grid), np.zeros((0, 3)), grid)

    @classmethod
    def from_table(cls, table: dict[str, Any], base: Path | None = None) -> World:
        """A hand-written world (the module's docstring has the keys)."""
        unknown = set(table) - {"walls", "boxes", "circles", "map"}
        if unknown:
            raise WorldError(f"unknown world keys: {', '.join(sorted(unknown))} "
                             "(walls, boxes, circles, map)")
        segments: list[tuple[float, float, float, float]] = []
        for i, line in enumerate(table.get("walls", [])):
            segments += _polyline(line, f"walls[{i}]")
        for i, box in enumerate(table.get("boxes", [])):
            if len(box) not in (4, 5):
                raise WorldError(f"boxes[{i}]: [cx, cy, width, height] or with yaw_deg, not {box}")
            yaw = math.radians(float(box[4])) if len(box) == 5 else 0.0
            segments += box_segments(float(box[0]), float(box[1]), float(box[2]), float(box[3]), yaw)
        circles = []
        for i, circle in enumerate(table.get("circles", [])):
            if len(circle) != 3 or not float(circle[2]) > 0:
                raise WorldError(f"circles[{i}]: [x, y, radius > 0], not {circle}")
            circles.append([float(v) for v in circle])
        grid = None
        seg = np.asarray(segments, dtype=float).reshape(-1, 4)
        if "map" in table:
            grid = load_map((base or Path.cwd()) / str(table["map"]))
            seg = np.concatenate((seg, grid_outline(grid)))
        return cls(seg, np.asarray(circles, dtype=float).reshape(-1, 3), grid)

    @classmethod
    def from_file(cls, path: str | Path) -> World:
        """A world from its file: a map_server YAML (``.yaml``/``.yml``, its occupied
        cells), or a hand-written world's TOML file (the geometry keys of
        ``from_table``, and ``name`` and ``description``; its ``map`` relative to it).
        ``WorldError`` says what is wrong with it (``OSError`` when it cannot be read)."""
        path = Path(path)
        if path.suffix in (".yaml", ".yml"):
            try:
                return cls.from_grid(load_map(path))
            except MapFileError as exc:             # it names the file already
                raise WorldError(str(exc)) from exc
        if path.suffix != ".toml":
            raise WorldError(f"{path}: a world is a map_server YAML (.yaml) or a TOML file (.toml)")
        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise WorldError(f"{path}: not valid TOML: {exc}") from exc
        table = {k: v for k, v in data.items() if k not in ("name", "description")}
        try:
            return cls.from_table(table, path.parent)
        except (MapFileError, TypeError, ValueError) as exc:
            raise WorldError(f"{path}: {exc}") from exc

    def occupancy(self, resolution: float = 0.05, margin: float = 0.5) -> OccupancyGrid:
        """The world as a ROS map (``/map``): the map it came from, if any; else its
        geometry drawn into a grid of ``resolution`` m cells over its bounding box and
        ``margin`` m around it (the origin at a whole number of cells), a cell
        occupied (100) where a wall or a circle passes through it, free (0) elsewhere.
        A hand-written world's map loses what is thinner than a cell; its occupied
        cells' outline (``from_grid``) lies within a cell of the geometry."""
        if self.grid is not None:
            return self.grid
        pts = [self.segments[:, :2], self.segments[:, 2:], self.circles[:, :2] - self.circles[:, 2:3],
               self.circles[:, :2] + self.circles[:, 2:3]]
        allpts = np.concatenate([p.reshape(-1, 2) for p in pts])
        if not len(allpts):
            return OccupancyGrid(np.zeros((1, 1), dtype=np.int8), resolution)
        lo = np.floor((allpts.min(axis=0) - margin) / resolution) * resolution
        hi = allpts.max(axis=0) + margin
        width, height = (int(v) for v in np.ceil((hi - lo) / resolution))
        data = np.zeros((height, width), dtype=np.int8)

        def mark(x: np.ndarray, y: np.ndarray) -> None:
            cols = np.floor((x - lo[0]) / resolution).astype(np.int64)
            rows = np.floor((y - lo[1]) / resolution).astype(np.int64)
            ok = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
            data[rows[ok], cols[ok]] = OCCUPIED

        step = resolution / 4
        for x0, y0, x1, y1 in self.segments:
            n = max(2, math.ceil(math.hypot(x1 - x0, y1 - y0) / step) + 1)
            u = np.linspace(0.0, 1.0, n)
            mark(x0 + u * (x1 - x0), y0 + u * (y1 - y0))
        for cx, cy, r in self.circles:
            n = max(8, math.ceil(2 * math.pi * r / step))
            a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
            for k in np.linspace(0.0, 1.0, max(2, math.ceil(r / step) + 1)):     # rings: a disc
                mark(cx + k * r * np.cos(a), cy + k * r * np.sin(a))
        return OccupancyGrid(data, resolution, (float(lo[0]), float(lo[1]), 0.0))

    @functools.cached_property
    def _ray_grid(self) -> RayGrid | None:
        return RayGrid.build(self.segments, self.circles)

    @property
    def ray_grid(self) -> RayGrid | None:
        """The C cast's grid over this geometry (built on first use); None without the
        C helper or without geometry."""
        return self._ray_grid

    def __getstate__(self) -> dict[str, Any]:
        # the grid holds C pointers: a copy builds its own
        return {k: v for k, v in self.__dict__.items() if k != "_ray_grid"}

    def cast(self, origins: np.ndarray, angles: np.ndarray, max_range: float = math.inf) -> np.ndarray:
        """For each ray (origin (K, 2) or one (2,), angle (K,) radians in the map
        frame): the distance to the first segment or circle it meets within
        ``max_range``, else ``inf``; ``cast_exact``'s figures, through the C grid."""
        grid = self._ray_grid
        if grid is None:
            return self.cast_exact(origins, angles, max_range)
        angles = np.asarray(angles, dtype=float)
        o = np.broadcast_to(np.asarray(origins, dtype=float), (*angles.shape, 2))
        return grid.cast(o[:, 0], o[:, 1], np.cos(angles), np.sin(angles), max_range)

    def cast_exact(self, origins: np.ndarray, angles: np.ndarray, max_range: float = math.inf
                   ) -> np.ndarray:
        """``cast`` with numpy, every ray against every segment and circle: the
        reference. A ray that starts inside a circle meets its rim; a ray parallel to
        a segment never meets it."""
        angles = np.asarray(angles, dtype=float)
        o = np.broadcast_to(np.asarray(origins, dtype=float), (*angles.shape, 2))
        dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]
        ox, oy = o[:, 0:1], o[:, 1:2]
        best = np.full(angles.shape, np.inf)
        if len(self.segments):
            x0, y0, x1, y1 = (self.segments[:, k][None, :] for k in range(4))
            ex, ey = x1 - x0, y1 - y0
            denom = dx * ey - dy * ex                        # cross(d, e)
            wx, wy = x0 - ox, y0 - oy
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (wx * ey - wy * ex) / denom              # along the ray
                u = (wx * dy - wy * dx) / denom              # along the segment
            hit = (denom != 0) & (t >= 0) & (u >= 0) & (u <= 1)
            best = np.minimum(best, np.where(hit, t, np.inf).min(axis=1))
        if len(self.circles):
            cx, cy, r = (self.circles[:, k][None, :] for k in range(3))
            fx, fy = ox - cx, oy - cy
            b = fx * dx + fy * dy
            c = fx * fx + fy * fy - r * r
            disc = b * b - c
            root = np.sqrt(np.maximum(disc, 0.0))
            near, far = -b - root, -b + root
            t = np.where(near >= 0, near, far)
            best = np.minimum(best, np.where((disc >= 0) & (t >= 0), t, np.inf).min(axis=1))
        return np.where(best <= max_range, best + 0.0, np.inf)          # + 0.0: no -0


def world_named(text: str) -> World:
    """A world's file (``World.from_file``: a map_server YAML or a hand-written world's
    TOML), or the name of a bundled one (``BUNDLED_WORLDS``: hospital_corridor,
    furnished_room). A ``ValueError`` names what is wrong (the bundled names among it)."""
    path = Path(text)
    if not path.suffix and len(path.parts) == 1:
        if any(c in text for c in "*?["):
            raise ValueError("a world's name has no wildcards")
        found = sorted(BUNDLED_WORLDS.glob(f"{text}.*"))
        found = [p for p in found if p.suffix in (".yaml", ".toml")]
        if not found:
            names = sorted({p.stem for p in BUNDLED_WORLDS.glob("*") if p.suffix in (".yaml", ".toml")})
            raise ValueError(f"no bundled world of that name ({', '.join(names)}), nor a file")
        path = found[0]
    try:
        return World.from_file(path)
    except OSError as exc:
        raise ValueError(f"cannot read {path}: {exc.strerror or exc}") from exc
