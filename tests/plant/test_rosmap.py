"""ROS map files load as map_server loads them: Nav2's own test map (PGM, PNG and BMP)
gives the cells Nav2's test expects, a map_saver map loads unchanged, the pixel rule
holds at its thresholds in every mode, a saved map loads back to the same cells, and
what map_server refuses is a ``MapFileError``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from PIL import Image

from wcdrive.plant.rosmap import MapFileError, MapMetadata, OccupancyGrid, load_map, occupancy, save_map

MAPS = Path(__file__).resolve().parents[1] / "data" / "rosmaps"

#: nav2_map_server/test/test_constants.cpp, g_valid_image_content: row-major from the
#: lower-left cell, as loadMapFromFile gives it.
NAV2_TESTMAP = np.array([
    [0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    [100, 100, 100, 100, 0, 0, 100, 100, 100, 0],
    [100, 100, 100, 100, 0, 0, 100, 100, 100, 0],
    [100, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    [100, 0, 0, 0, 0, 0, 0, 0, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 100, 100, 0, 0],
    [100, 0, 0, 0, 0, 0, 0, 0, 0, 0],
], dtype=np.int8)


@pytest.mark.parametrize("image", ["testmap.png", "testmap.pgm", "testmap.bmp"])
def test_nav2s_test_map_loads_to_the_cells_nav2s_test_expects(image: str, tmp_path: Path) -> None:
    yaml_path = tmp_path / "testmap.yaml"
    yaml_path.write_text((MAPS / "testmap.yaml").read_text().replace("testmap.png", str(MAPS / image)))
    grid = load_map(yaml_path)
    assert (grid.width, grid.height, grid.resolution, grid.origin) == (10, 10, 0.1, (2.0, 3.0, 1.0))
    assert np.array_equal(grid.data, NAV2_TESTMAP)


def test_the_image_path_is_relative_to_the_yaml() -> None:
    assert np.array_equal(load_map(MAPS / "testmap.yaml").data, NAV2_TESTMAP)


def test_a_map_saver_map_loads_unchanged() -> None:
    """tb3_sandbox: written by map_saver (no ``mode``: trinary), 384 x 384 cells of 5 cm
    from (-10, -10); its grey levels are 0, 205 and 254, so every cell is one of the
    three values and their counts are the image's."""
    grid = load_map(MAPS / "tb3_sandbox.yaml")
    with Image.open(MAPS / "tb3_sandbox.pgm") as img:
        pixels = np.asarray(img)
    assert (grid.width, grid.height) == (pixels.shape[1], pixels.shape[0])
    assert grid.resolution == 0.05 and grid.origin == (-10.0, -10.0, 0.0)
    assert set(np.unique(pixels)) <= {0, 205, 254}
    for level, value in ((0, 100), (254, 0), (205, -1)):
        assert np.count_nonzero(grid.data == value) == np.count_nonzero(pixels == level) > 0
    # the flip: the image's top row is the map's last
    assert np.array_equal(grid.data[-1], np.where(pixels[0] == 0, 100, np.where(pixels[0] == 254, 0, -1)))


def _meta(mode: str = "trinary", negate: bool = False, free: float = 0.196, occupied: float = 0.65
          ) -> MapMetadata:
    return MapMetadata(Path("x.pgm"), 0.05, (0.0, 0.0, 0.0), free, occupied, mode, negate)


def test_the_pixel_rule_at_its_thresholds() -> None:
    """occ = 1 - p/255 in binary32: p = 89 gives occ 0.6509804 (>= 0.65: occupied), p = 90
    0.64705884 (unknown); p = 205 gives 0.19607842 (unknown at free 0.196), p = 206
    0.19215685 (free). negate reads p/255 instead (89: 0.349, unknown; 205: 0.804,
    occupied); scale puts the unknowns on 0..100 by their place between the thresholds."""
    grey = np.array([[0, 89, 90, 205, 206, 254, 255]], dtype=np.uint8)
    assert occupancy(grey, _meta()).tolist() == [[100, 100, -1, -1, 0, 0, 0]]
    assert occupancy(grey, _meta(negate=True)).tolist() == [[0, -1, -1, 100, 100, 100, 100]]
    # 90: occ 0.64705884 -> 100 (0.647 - 0.196) / (0.65 - 0.196) = 99.35 -> 99
    # 205: occ 0.19607842 -> 0.0173 -> 0
    assert occupancy(grey, _meta("scale")).tolist() == [[100, 100, 99, 0, 0, 0, 0]]
    raw = np.array([[0, 1, 100, 101, 200, 255]], dtype=np.uint8)
    assert occupancy(raw, _meta("raw")).tolist() == [[0, 1, 100, -1, -1, -1]]


def test_transparent_pixels_are_unknown(tmp_path: Path) -> None:
    rgba = np.zeros((2, 2, 4), dtype=np.uint8)
    rgba[..., 3] = [[255, 0], [254, 255]]                       # black: occupied where opaque
    Image.fromarray(rgba, mode="RGBA").save(tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text("image: m.png\nresolution: 1\norigin: [0, 0, 0]\nnegate: false\n"
                                     "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert load_map(tmp_path / "m.yaml").data.tolist() == [[-1, 100], [100, -1]]   # flipped


@given(hnp.arrays(np.int8, hnp.array_shapes(min_dims=2, max_dims=2, max_side=12),
                  elements=st.sampled_from([-1, 0, 100])),
       st.floats(-50, 50), st.floats(-50, 50), st.floats(-3.1, 3.1))
def test_a_saved_map_loads_back_to_the_same_cells(cells: np.ndarray, x: float, y: float, yaw: float) -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        grid = OccupancyGrid(cells, 0.05, (round(x, 3), round(y, 3), yaw))
        back = load_map(save_map(grid, Path(tmp) / "saved"))
    assert np.array_equal(back.data, cells)
    assert back.resolution == 0.05 and back.origin[:2] == grid.origin[:2]
    assert math.isclose(back.origin[2], yaw, abs_tol=1e-6)


def test_cells_and_points_in_the_map_frame() -> None:
    """The lower-left cell's outer corner is the origin; yaw turns the grid about it."""
    data = np.zeros((3, 4), dtype=np.int8)
    data[0, 1] = 100
    grid = OccupancyGrid(data, 0.5, (1.0, 2.0, 0.0))
    assert grid.occupied_centres().tolist() == [[1.75, 2.25]]
    assert grid.value_at(1.6, 2.1) == 100 and grid.value_at(1.4, 2.1) == 0 and grid.value_at(0.9, 2.1) == -1
    turned = OccupancyGrid(data, 0.5, (1.0, 2.0, math.pi / 2))
    [(cx, cy)] = turned.occupied_centres().tolist()
    assert math.isclose(cx, 0.75) and math.isclose(cy, 2.75)
    assert turned.value_at(cx, cy) == 100 and turned.cell_of(cx, cy) == (0, 1)


@pytest.mark.parametrize(("text", "why"), [
    ("resolution: 1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n", "no 'image'"),
    ("image: m.pgm\nresolution: 1\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
     "3 elements"),
    ("image: m.pgm\nresolution: 1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
     "no 'negate'"),
    ("image: m.pgm\nmode: fuzzy\nresolution: 1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "none of"),
    ("image: m.pgm\nresolution: one\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.2\n",
     "must be a number"),
    ("image: gone.pgm\nresolution: 1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\n"
     "free_thresh: 0.2\n", "cannot read the map image"),
])
def test_what_map_server_refuses_is_a_map_file_error(text: str, why: str, tmp_path: Path) -> None:
    Image.fromarray(np.zeros((2, 2), dtype=np.uint8)).save(tmp_path / "m.pgm")
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(MapFileError, match=why):
        load_map(tmp_path / "bad.yaml")
