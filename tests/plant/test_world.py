"""The world's geometry and its exact ray cast: rays to walls, boxes and posts whose
lengths are worked out by hand, the same hits as pymunk's ``segment_query_first`` on
random rays, and a ROS map's outline, whose every hit lies where a free cell meets an
occupied one."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pymunk
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wcdrive.plant.rosmap import OccupancyGrid, load_map
from wcdrive.plant.world import World, WorldError, grid_outline

MAPS = Path(__file__).resolve().parents[1] / "data" / "rosmaps"


def _one(world: World, x: float, y: float, heading_deg: float, max_range: float = math.inf) -> float:
    return float(world.cast(np.array([x, y]), np.array([math.radians(heading_deg)]), max_range)[0])


def test_rays_to_known_walls() -> None:
    """A wall x = 5 from y = -1 to 5: 5 m straight on, 5 sqrt(2) m at 45 deg (it meets
    the wall at y = 5, its end), nothing at 46 deg (y = 5.18, past it) nor behind; a
    post of radius 0.5 at (3, -3): 3 sqrt(2) - 0.5 m at -45 deg, and its radius from
    its centre."""
    world = World.from_table({"walls": [[5, -1, 5, 5]], "circles": [[3, -3, 0.5]]})
    assert _one(world, 0, 0, 0) == 5.0
    assert math.isclose(_one(world, 0, 0, 45), 5 * math.sqrt(2))
    assert _one(world, 0, 0, 46) == math.inf and _one(world, 0, 0, 180) == math.inf
    assert math.isclose(_one(world, 0, 0, -45), 3 * math.sqrt(2) - 0.5)
    assert math.isclose(_one(world, 3, -3, 123), 0.5)
    assert _one(world, 0, 0, 0, max_range=4.9) == math.inf and _one(world, 0, 0, 0, max_range=5.0) == 5.0


def test_a_box_from_inside_and_a_polyline() -> None:
    """A 2 x 1 box turned 90 deg about (1, 1): from its centre 0.5 m along x and 1 m
    along y. A corridor's two walls as polylines 1.2 m apart."""
    box = World.from_table({"boxes": [[1, 1, 2, 1, 90]]})
    assert math.isclose(_one(box, 1, 1, 0), 0.5) and math.isclose(_one(box, 1, 1, 90), 1.0)
    corridor = World.from_table({"walls": [[0, 0, 20, 0], [0, 1.2, 8, 1.2, 8, 3, 9, 3, 9, 1.2, 20, 1.2]]})
    assert math.isclose(_one(corridor, 4, 0.6, 90), 0.6) and math.isclose(_one(corridor, 4, 0.6, -90), 0.6)
    assert math.isclose(_one(corridor, 8.5, 0.6, 90), 2.4)       # the doorway's alcove


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_the_cast_meets_what_pymunk_meets(seed: int) -> None:
    """Random walls and posts, 200 random rays: the same first hit as pymunk's
    ``Space.segment_query_first`` (radius-0 segments and circles) to 1e-9 m."""
    rng = np.random.default_rng(seed)
    segments = rng.uniform(-10, 10, (12, 4))
    circles = np.column_stack((rng.uniform(-10, 10, (5, 2)), rng.uniform(0.05, 1.0, 5)))
    world = World(segments, circles)
    space = pymunk.Space()
    body = space.static_body
    space.add(*[pymunk.Segment(body, (s[0], s[1]), (s[2], s[3]), 0.0) for s in segments])
    space.add(*[pymunk.Circle(body, c[2], (c[0], c[1])) for c in circles])
    origins = rng.uniform(-12, 12, (200, 2))
    angles = rng.uniform(-math.pi, math.pi, 200)
    ranges = world.cast(origins, angles, 40.0)
    for (x, y), a, got in zip(origins, angles, ranges, strict=True):
        end = (x + 40.0 * math.cos(a), y + 40.0 * math.sin(a))
        hit = space.segment_query_first((x, y), end, 0.0, pymunk.ShapeFilter())
        inside = any(math.hypot(x - c[0], y - c[1]) < c[2] for c in circles)
        if inside:
            continue                    # pymunk reports a ray from inside a circle at 0
        want = math.inf if hit is None else hit.alpha * 40.0
        assert (got == want == math.inf) or math.isclose(got, want, abs_tol=1e-9), (x, y, a, got, want)


def test_a_grid_cell_outline() -> None:
    """One occupied cell, 0.1 m, the origin at (1, 2): a 0.1 m square from (1, 2); an L
    of three cells: six edges after merging."""
    data = np.zeros((3, 3), dtype=np.int8)
    data[0, 0] = 100
    square = World.from_grid(OccupancyGrid(data, 0.1, (1.0, 2.0, 0.0)))
    assert len(square.segments) == 4
    assert math.isclose(_one(square, 0.5, 2.05, 0), 0.5) and math.isclose(_one(square, 1.05, 3.0, -90), 0.9)
    data[0, 1] = data[1, 0] = 100
    assert len(grid_outline(OccupancyGrid(data, 0.1))) == 6


def test_every_hit_on_a_ros_map_is_where_free_meets_occupied() -> None:
    """tb3_sandbox (a map_saver map): 2,000 rays from random free cells; just short of
    each hit the cell is not occupied, just past it the cell is."""
    grid = load_map(MAPS / "tb3_sandbox.yaml")
    world = World.from_grid(grid)
    rng = np.random.default_rng(1)
    rows, cols = np.nonzero(grid.data == 0)
    pick = rng.choice(len(rows), 2000)
    origins = grid.cell_centres(rows[pick], cols[pick])
    angles = rng.uniform(-math.pi, math.pi, 2000)
    ranges = world.cast(origins, angles, 30.0)
    assert np.isfinite(ranges).mean() > 0.99             # the sandbox is walled in
    for (x, y), a, r in zip(origins, angles, ranges, strict=True):
        if not np.isfinite(r):
            continue
        before = grid.value_at(x + (r - 1e-6) * math.cos(a), y + (r - 1e-6) * math.sin(a))
        after = grid.value_at(x + (r + 1e-6) * math.cos(a), y + (r + 1e-6) * math.sin(a))
        assert before != 100 and after == 100, (x, y, a, r)


@pytest.mark.parametrize(("table", "why"), [
    ({"walls": [[0, 0, 1]]}, "x, y pairs"),
    ({"boxes": [[0, 0, 1]]}, r"\[cx, cy, width, height\]"),
    ({"boxes": [[0, 0, 0, 1]]}, "positive width"),
    ({"circles": [[0, 0, -1]]}, "radius > 0"),
    ({"wall": []}, "unknown world keys: wall"),
])
def test_a_bad_world_table_is_an_error(table: dict, why: str) -> None:
    with pytest.raises(WorldError, match=why):
        World.from_table(table)


def test_a_world_table_may_name_a_ros_map() -> None:
    world = World.from_table({"map": "tb3_sandbox.yaml", "circles": [[0, 0, 0.1]]}, base=MAPS)
    assert world.grid is not None and len(world.segments) > 100 and len(world.circles) == 1
