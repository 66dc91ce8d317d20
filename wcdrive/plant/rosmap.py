"""ROS map files (a map_server YAML and its PGM/PNG/BMP image) read and written as
Nav2's ``map_io`` (Jazzy) does: ``load_map(yaml_path)`` gives the ``OccupancyGrid``
that ``map_server`` would publish, ``save_map(grid, stem)`` writes what
``map_saver_cli`` writes (trinary).

    grid = load_map("maps/warehouse.yaml")
    grid.value_at(1.0, 2.0)          # -1 unknown, 0 free, 100 occupied
    grid.occupied_centres()          # (N, 2) cell centres in the map frame, metres

Loading, as ``nav2_map_server/src/map_io.cpp``:

- YAML keys ``image`` (relative to the YAML's directory unless absolute),
  ``resolution``, ``origin`` (exactly 3 numbers: x, y, yaw of the lower-left pixel),
  ``free_thresh``, ``occupied_thresh``, ``mode`` (``trinary`` when absent, ``scale``,
  ``raw``) and ``negate`` (an int, or a bool); a missing key is a ``MapFileError``.
- The image is made greyscale (a grey image as it is; colour as luma), each pixel
  ``p`` becomes ``occ = 1 - p / 255`` (``p / 255`` when ``negate``) in binary32, as the
  Eigen code computes it; ``occ >= occupied_thresh`` is 100, ``occ <= free_thresh`` is
  0, else -1 (trinary) or ``round(100 (occ - free) / (occ_th - free))`` (scale). A
  pixel whose alpha is below 255 is -1 (trinary and scale). ``raw``: the grey value
  itself, -1 outside 0..100.
- Rows are flipped: ``data`` is row-major from the lower-left cell, as ``nav_msgs/
  OccupancyGrid``'s.

Colour images: GraphicsMagick's grey is Rec. 601 luma in its own rounding, Pillow's
(``convert("L")``) the same weights in integer arithmetic, so a colour pixel can land
one grey level apart; maps are grey in practice (``map_saver`` writes grey PGM).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from PIL import Image

from wcdrive.errors import WcdriveFileError

MODES = ("trinary", "scale", "raw")
UNKNOWN, FREE, OCCUPIED = -1, 0, 100
#: What map_saver writes for a trinary map (grey levels) and in its YAML.
SAVED_OCCUPIED, SAVED_FREE, SAVED_UNKNOWN = 0, 254, 205
SAVED_OCCUPIED_THRESH, SAVED_FREE_THRESH = 0.65, 0.196


class MapFileError(WcdriveFileError):
    """A map YAML or image that map_server would refuse (the message says why)."""


@dataclass(frozen=True)
class MapMetadata:
    """The YAML's contents, the image path made absolute."""

    image: Path
    resolution: float
    origin: tuple[float, float, float]
    free_thresh: float
    occupied_thresh: float
    mode: str = "trinary"
    negate: bool = False


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """``nav_msgs/OccupancyGrid``'s content: ``data`` (height, width) int8, row 0 the
    bottom row (``data.ravel()`` is the message's ``data``), ``resolution`` m/cell,
    ``origin`` the pose (x, y, yaw) of the lower-left cell's outer corner."""

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def width(self) -> int:
        """Cells per row."""
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        """Rows."""
        return int(self.data.shape[0])

    def cell_centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N, 2) map-frame centres of the cells (``rows``, ``cols``), the origin's yaw
        applied."""
        x0, y0, yaw = self.origin
        u = (np.asarray(cols, dtype=float) + 0.5) * self.resolution
        v = (np.asarray(rows, dtype=float) + 0.5) * self.resolution
        c, s = math.cos(yaw), math.sin(yaw)
        return np.column_stack((x0 + c * u - s * v, y0 + s * u + c * v))

    def occupied_centres(self) -> np.ndarray:
        """(N, 2) map-frame centres of the occupied cells (value 100)."""
        rows, cols = np.nonzero(self.data == OCCUPIED)
        return self.cell_centres(rows, cols)

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, col) of the cell holding map-frame point (x, y), or None outside."""
        x0, y0, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = x - x0, y - y0
        col = math.floor((c * dx + s * dy) / self.resolution)
        row = math.floor((-s * dx + c * dy) / self.resolution)
        if 0 <= row < self.height and 0 <= col < self.width:
            return row, col
        return None

    def value_at(self, x: float, y: float) -> int:
        """The cell value at map-frame (x, y): -1 unknown (outside too), 0..100."""
        cell = self.cell_of(x, y)
        return UNKNOWN if cell is None else int(self.data[cell])


def _require(doc: dict[str, Any], key: str, path: Path) -> Any:
    if key not in doc or doc[key] is None:
        raise MapFileError(f"{path}: the map YAML has no '{key}'")
    return doc[key]


def _number(doc: dict[str, Any], key: str, path: Path) -> float:
    value = _require(doc, key, path)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MapFileError(f"{path}: '{key}' must be a number, not {value!r}")
    return float(value)


def load_map_yaml(path: str | Path) -> MapMetadata:
    """The metadata of a map_server YAML (``MapFileError`` for what map_server
    refuses: a missing key, an origin without 3 elements, an unknown mode)."""
    path = Path(path).expanduser()
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise MapFileError(f"{path}: cannot read the map YAML: {exc}") from exc
    if not isinstance(doc, dict):
        raise MapFileError(f"{path}: the map YAML is not a mapping")
    image = str(_require(doc, "image", path))
    if not image:
        raise MapFileError(f"{path}: the image tag is empty")
    image_path = Path(image) if image.startswith("/") else path.parent / image
    origin = _require(doc, "origin", path)
    if not isinstance(origin, list) or len(origin) != 3:
        raise MapFileError(f"{path}: 'origin' must have 3 elements, not {origin!r}")
    mode = str(doc.get("mode") or "trinary").lower()
    if mode not in MODES:
        raise MapFileError(f"{path}: mode {mode!r} is none of {', '.join(MODES)}")
    negate = _require(doc, "negate", path)
    if not isinstance(negate, (bool, int)):
        raise MapFileError(f"{path}: 'negate' must be 0, 1, true or false, not {negate!r}")
    return MapMetadata(image_path, _number(doc, "resolution", path),
                       (float(origin[0]), float(origin[1]), float(origin[2])),
                       _number(doc, "free_thresh", path), _number(doc, "occupied_thresh", path),
                       mode, bool(negate))


def occupancy(grey: np.ndarray, meta: MapMetadata, alpha: np.ndarray | None = None) -> np.ndarray:
    """map_io's pixel rule on a (rows, cols) uint8 grey image, top row first: the
    cell values, top row first (not yet flipped)."""
    grey = np.asarray(grey, dtype=np.uint8)
    if meta.mode == "raw":
        raw = grey.astype(np.int8)
        return np.where((raw < FREE) | (raw > OCCUPIED), np.int8(UNKNOWN), raw).astype(np.int8)
    normalized = grey.astype(np.float32) / np.float32(255.0)
    if not meta.negate:
        normalized = np.float32(1.0) - normalized
    wide = normalized.astype(np.float64)                # Eigen compares the float as a double
    out = np.full(grey.shape, UNKNOWN, dtype=np.int8)
    out[wide >= meta.occupied_thresh] = OCCUPIED
    out[wide <= meta.free_thresh] = FREE
    if meta.mode == "scale":
        between = (wide > meta.free_thresh) & (wide < meta.occupied_thresh)
        scaled = ((normalized - np.float32(meta.free_thresh))
                  / np.float32(meta.occupied_thresh - meta.free_thresh)) * np.float32(100.0)
        out[between] = np.round(scaled[between]).astype(np.int8)
    if alpha is not None:
        out[np.asarray(alpha) < 255] = UNKNOWN
    return out


def load_map(path: str | Path) -> OccupancyGrid:
    """The ``OccupancyGrid`` map_server publishes for the map YAML at ``path``."""
    meta = load_map_yaml(path)
    try:
        with Image.open(meta.image) as img:
            img.load()
            alpha = np.asarray(img.getchannel("A")) if "A" in img.getbands() else None
            grey = np.asarray(img.convert("L"))
    except OSError as exc:
        raise MapFileError(f"{path}: cannot read the map image {meta.image}: {exc}") from exc
    cells = occupancy(grey, meta, alpha if meta.mode != "raw" else None)
    return OccupancyGrid(np.ascontiguousarray(cells[::-1]), meta.resolution, meta.origin)


def save_map(grid: OccupancyGrid, stem: str | Path) -> Path:
    """Writes ``<stem>.pgm`` and ``<stem>.yaml`` as ``map_saver_cli`` does in trinary
    mode with its default thresholds (free up to 25, occupied from 65; grey 254 / 0 /
    205); returns the YAML's path."""
    stem = Path(stem)
    free_int, occupied_int = round(0.25 * 100.0), round(0.65 * 100.0)
    cells = grid.data[::-1]
    pixels = np.full(cells.shape, SAVED_UNKNOWN, dtype=np.uint8)
    known = (cells >= 0) & (cells <= 100)
    pixels[known & (cells <= free_int)] = SAVED_FREE
    pixels[known & (cells >= occupied_int)] = SAVED_OCCUPIED
    image = stem.with_suffix(".pgm")
    Image.fromarray(pixels, mode="L").save(image)
    x, y, yaw = grid.origin
    meta = stem.with_suffix(".yaml")
    meta.write_text(
        f"image: {image.name}\nmode: trinary\nresolution: {grid.resolution:.3f}\n"
        f"origin: [{x:.3f}, {y:.3f}, {yaw:.7g}]\nnegate: 0\n"
        f"occupied_thresh: {SAVED_OCCUPIED_THRESH}\nfree_thresh: {SAVED_FREE_THRESH}\n")
    return meta
