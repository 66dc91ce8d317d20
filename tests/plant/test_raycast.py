"""The C ray cast (``wcdrive.plant.raycast``) against the numpy reference
(``World.cast_exact``) and pymunk's ``segment_query_first``: the same distances, bit for
bit against the reference, on random rays over random worlds, over the tb3_sandbox
map's outline whatever the grid's cell size, and on rays worked out by hand (a wall
straight on, a segment's end grazed, a ray along a wall, an origin on a wall, the range
limit); ``World.cast`` without the C helper is the reference."""

from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import pymunk
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wcdrive.plant import raycast
from wcdrive.plant.lidar import Lidar
from wcdrive.plant.raycast import RayGrid
from wcdrive.plant.rosmap import load_map
from wcdrive.plant.world import World

MAPS = Path(__file__).resolve().parents[1] / "data" / "rosmaps"


@pytest.fixture(scope="module")
def sandbox() -> World:
    return World.from_grid(load_map(MAPS / "tb3_sandbox.yaml"))


def _c(world: World, origins: np.ndarray, angles: np.ndarray, max_range: float = math.inf,
       cell_factor: float = raycast.CELL_FACTOR) -> np.ndarray:
    grid = RayGrid.build(world.segments, world.circles, cell_factor)
    assert grid is not None, "the C ray cast was not built (a C compiler is needed)"
    angles = np.asarray(angles, dtype=float)
    o = np.broadcast_to(np.asarray(origins, dtype=float), (*angles.shape, 2))
    return grid.cast(o[:, 0], o[:, 1], np.cos(angles), np.sin(angles), max_range)


def _same(got: np.ndarray, want: np.ndarray, tol: float = 1e-9) -> None:
    """The same rays meet nothing, and the others agree within ``tol`` metres."""
    assert got.shape == want.shape
    miss_got, miss_want = np.isinf(got), np.isinf(want)
    bad = np.flatnonzero(miss_got != miss_want)
    assert not bad.size, f"{bad.size} rays differ in hit or miss, first {got[bad[0]]} vs {want[bad[0]]}"
    hit = ~miss_want
    if hit.any():
        worst = int(np.argmax(np.abs(got[hit] - want[hit])))
        assert abs(got[hit][worst] - want[hit][worst]) <= tol, (got[hit][worst], want[hit][worst])


def _exact_in_chunks(world: World, origins: np.ndarray, angles: np.ndarray, max_range: float = math.inf
                     ) -> np.ndarray:
    return np.concatenate([world.cast_exact(origins[i:i + 1000], angles[i:i + 1000], max_range)
                           for i in range(0, len(angles), 1000)])


def _one(world: World, x: float, y: float, angle: float, max_range: float = math.inf) -> float:
    """One ray by the C cast, checked against the reference."""
    got = _c(world, np.array([x, y]), np.array([angle]), max_range)
    want = world.cast_exact(np.array([x, y]), np.array([angle]), max_range)
    assert got.tobytes() == want.tobytes(), (got, want)
    return float(got[0])


def test_rays_worked_out_by_hand() -> None:
    """A wall x = 5 from y = -1 to 5 and a post of radius 0.5 at (3, -3): from (1, 1)
    straight on 4 m; along y = 5 the ray meets the wall's end (u = 1 exactly), a hair
    above it nothing; on the wall 0 m either way; past ``max_range`` nothing; the post
    3 sqrt(2) - 0.5 m away at -45 deg and 0.5 m from its centre (inside: the rim)."""
    world = World.from_table({"walls": [[5, -1, 5, 5]], "circles": [[3, -3, 0.5]]})
    assert _one(world, 1, 1, 0.0) == 4.0
    assert _one(world, 0, 5, 0.0) == 5.0 and _one(world, 0, -1, 0.0) == 5.0     # both ends grazed
    assert _one(world, 0, 5 + 1e-9, 0.0) == math.inf and _one(world, 0, -1 - 1e-9, 0.0) == math.inf
    assert _one(world, 5, 2, 0.0) == 0.0 and _one(world, 5, 2, math.pi) == 0.0   # origin on the wall
    assert _one(world, 1, 1, 0.0, max_range=3.999) == math.inf
    assert _one(world, 1, 1, 0.0, max_range=4.0) == 4.0
    assert _one(world, 1, 1, math.pi) == math.inf                                 # facing away
    assert math.isclose(_one(world, 0, 0, -math.pi / 4), 3 * math.sqrt(2) - 0.5)
    assert _one(world, 3, -3, 2.0) == 0.5 and _one(world, 3.25, -3, 0.0) == 0.25
    assert _one(world, 0, -3.5, 0.0) == 3.0                                       # tangent to the post


def test_a_ray_along_a_wall_meets_what_lies_beyond() -> None:
    """A ray along a wall never meets it (parallel), from before it, on it or from its
    end; it meets the wall across its path at x = 12, and the joint of a polyline's two
    segments from either side."""
    world = World.from_table({"walls": [[0, 0, 10, 0], [12, -1, 12, 1], [20, -2, 22, 0, 20, 2]]})
    for x in (-1.0, 0.0, 4.0, 10.0):
        assert _one(world, x, 0, 0.0) == 12.0 - x
    assert _one(world, 13, 0, 0.0) == 9.0                                         # the joint at (22, 0)
    assert _one(world, 13, 0, math.pi) == 1.0


def test_rays_from_outside_the_grid() -> None:
    """Origins far outside the geometry's bounding box, towards it and away from it; a
    ray that passes beside it; an empty world meets nothing."""
    world = World.from_table({"boxes": [[0, 0, 2, 2]]})
    assert _one(world, -1000, 0, 0.0) == 999.0 and _one(world, 0, 1000, -math.pi / 2) == 999.0
    assert _one(world, -1000, 0, math.pi) == math.inf and _one(world, -1000, 5, 0.0) == math.inf
    assert math.isclose(_one(world, -10, -10, math.pi / 4), 9 * math.sqrt(2))    # at the corner
    assert RayGrid.build(np.zeros((0, 4)), np.zeros((0, 3))) is None
    assert World().cast(np.zeros(2), np.zeros(3)).tolist() == [math.inf] * 3


def _random_world(rng: np.random.Generator, n_seg: int, n_circ: int, span: float = 10.0) -> World:
    """Long, short and axis-aligned segments, and posts."""
    segments = rng.uniform(-span, span, (n_seg, 4))
    short = rng.random(n_seg) < 0.4
    segments[short, 2:] = segments[short, :2] + rng.uniform(-0.5, 0.5, (short.sum(), 2))
    flat = rng.random(n_seg) < 0.3
    segments[flat, 3] = segments[flat, 1]
    circles = np.column_stack((rng.uniform(-span, span, (n_circ, 2)), rng.uniform(0.05, 1.5, n_circ)))
    return World(segments, circles)


def _random_rays(rng: np.random.Generator, world: World, k: int, span: float = 12.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Origins anywhere, on segments' ends and on segments; angles anywhere and along
    the axes."""
    origins = rng.uniform(-span, span, (k, 2))
    if len(world.segments):
        pick = rng.integers(0, len(world.segments), k)
        u = rng.choice([0.0, 0.5, 1.0, rng.random()], k)[:, None]
        s = world.segments[pick]
        on = rng.random(k) < 0.2
        origins[on] = (s[:, :2] + u * (s[:, 2:] - s[:, :2]))[on]
    angles = rng.uniform(-math.pi, math.pi, k)
    axis = rng.random(k) < 0.15
    angles[axis] = rng.integers(-4, 4, axis.sum()) * (math.pi / 2)
    return origins, angles


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 40), st.integers(0, 8), st.sampled_from([0.3, 1.0, 3.0]),
       st.sampled_from([math.inf, 5.0]))
def test_the_c_cast_is_the_reference_on_random_worlds(seed: int, n_seg: int, n_circ: int, cell: float,
                                                      max_range: float) -> None:
    rng = np.random.default_rng(seed)
    world = _random_world(rng, n_seg, n_circ)
    if n_seg + n_circ == 0:
        return
    origins, angles = _random_rays(rng, world, 300)
    want = world.cast_exact(origins, angles, max_range)
    got = _c(world, origins, angles, max_range, cell)
    _same(got, want)
    assert got.tobytes() == want.tobytes()          # the same operations: bit for bit


def _distance_to_items(world: World, x: float, y: float) -> float:
    """How far the point (x, y) is from the nearest segment or circle's rim."""
    s = world.segments
    near = math.inf
    if len(s):
        ex, ey = s[:, 2] - s[:, 0], s[:, 3] - s[:, 1]
        length2 = np.maximum(ex * ex + ey * ey, 1e-300)
        u = np.clip(((x - s[:, 0]) * ex + (y - s[:, 1]) * ey) / length2, 0, 1)
        near = float(np.hypot(s[:, 0] + u * ex - x, s[:, 1] + u * ey - y).min())
    c = world.circles
    if len(c):
        near = min(near, float(np.abs(np.hypot(c[:, 0] - x, c[:, 1] - y) - c[:, 2]).min()))
    return near


def _same_but_where_the_reference_misses_its_item(world: World, origins: np.ndarray, angles: np.ndarray,
                                                  got: np.ndarray, want: np.ndarray) -> None:
    """``got`` is ``want`` bit for bit, but where the reference's hit is rounding noise:
    a ray within an ulp of parallel to a segment whose line passes through its origin
    gets t = 0 and a u that says nothing; the reference may then report a hit at a
    point off every item, which the C cast, testing only the items near the ray, does
    not. There the C cast's own hit is further on."""
    for i in np.flatnonzero(got.view(np.int64) != want.view(np.int64)):
        x, y = origins[i] + want[i] * np.array([math.cos(angles[i]), math.sin(angles[i])])
        assert got[i] > want[i] and _distance_to_items(world, x, y) > 1e-6, (origins[i], angles[i], got[i])


lattice = st.integers(-6, 6).map(float)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(lattice, lattice, lattice, lattice), min_size=1, max_size=12),
       st.lists(st.tuples(lattice, lattice, st.sampled_from([0.5, 1.0, 2.0])), max_size=3),
       st.lists(st.tuples(lattice, lattice, st.integers(-8, 8)), min_size=1, max_size=20),
       st.sampled_from([0.25, 1.0, 4.0]))
def test_degenerate_geometry_on_a_lattice(segments: list, circles: list, rays: list, cell: float) -> None:
    """Walls, posts and origins on integer points, rays at multiples of 45 deg: rays
    through ends and joints, along walls, from walls. The reference's distances, but
    where its own hit is rounding noise off every item."""
    world = World(np.array(segments, dtype=float).reshape(-1, 4),
                  np.array(circles, dtype=float).reshape(-1, 3))
    origins = np.array([r[:2] for r in rays], dtype=float)
    angles = np.array([r[2] * math.pi / 4 for r in rays])
    want = world.cast_exact(origins, angles)
    got = _c(world, origins, angles, math.inf, cell)
    _same_but_where_the_reference_misses_its_item(world, origins, angles, got, want)


def test_a_ray_within_an_ulp_of_parallel_off_a_segment_s_end() -> None:
    """From (-4, -2) on the line of the segment (-3, -1)-(4, 6), away from it at 225
    deg (cos and sin an ulp apart): the reference's t is 0 and its u rounding noise,
    a hit 1.4 m off the segment; the C cast, its cells smaller than that, meets
    nothing, as the ray does (it passes the post 2 sqrt(2) m from its centre)."""
    world = World(np.array([[4.0, 6.0, -3.0, -1.0]]), np.array([[-4.0, -6.0, 2.0]]))
    origin, angle = np.array([-4.0, -2.0]), np.array([5 * math.pi / 4])
    assert world.cast_exact(origin, angle)[0] == 0.0
    got = _c(world, origin, angle, math.inf, 0.2)
    _same_but_where_the_reference_misses_its_item(world, origin[None, :], angle, got,
                                                  world.cast_exact(origin, angle))
    assert got[0] == math.inf


@pytest.mark.parametrize("cell", [0.25, 0.6, 1.0, 2.5, 8.0])
def test_the_c_cast_is_the_reference_on_a_ros_map(sandbox: World, cell: float) -> None:
    """tb3_sandbox's outline (756 segments): 4,000 rays from anywhere in and around the
    map, each of them from the origin of a lidar scan, for grids of cells from a
    quarter of a typical to eight times; and a whole S3 turn from a few poses."""
    rng = np.random.default_rng(int(cell * 100))
    origins, angles = _random_rays(rng, sandbox, 4000, span=4.0)
    want = _exact_in_chunks(sandbox, origins, angles)
    assert np.isfinite(want).mean() > 0.5
    got = _c(sandbox, origins, angles, math.inf, cell)
    _same(got, want)
    assert got.tobytes() == want.tobytes()
    sweep = np.linspace(-math.pi, math.pi, 3200, endpoint=False)
    for x, y in ((0.0, 0.0), (-1.7, 1.3), (2.0, -2.0)):
        assert _c(sandbox, np.array([x, y]), sweep, 40.0, cell).tobytes() == \
            _exact_in_chunks(sandbox, np.tile([x, y], (3200, 1)), sweep, 40.0).tobytes()


def test_a_wall_an_ulp_off_a_cell_edge_is_met() -> None:
    """A wall whose x lies an ulp or two either side of a cell's edge (where the cell a
    point is binned in and the cell's own bounds, each rounded, may disagree): the ray
    across it meets it."""
    frame = [[-5.0, -5.0, 5.0, -5.0], [5.0, -5.0, 5.0, 5.0], [5.0, 5.0, -5.0, 5.0], [-5.0, 5.0, -5.0, -5.0]]
    probe = RayGrid.build(np.array([*frame, [0.1, -1.0, 0.1, 1.0]]), np.zeros((0, 3)))
    assert probe is not None
    x0, cs = probe.corner[0], probe.cell
    tried = 0
    for k in range(1, probe.shape[1]):
        edge = x0 + k * cs
        for n in range(-3, 4):
            x = edge + n * math.ulp(edge)
            if not -4.5 < x < 4.5:
                continue
            world = World(np.array([*frame, [x, -1.0, x, 1.0]]), np.zeros((0, 3)))
            grid = RayGrid.build(world.segments, world.circles)
            assert grid is not None and (grid.corner, grid.cell) == (probe.corner, cs)
            got = grid.cast(np.array([-4.75]), np.zeros(1), np.ones(1), np.zeros(1))
            assert got[0] == x + 4.75, (k, n)
            tried += 1
    assert tried >= 10


def test_the_grid_on_a_ros_map_is_sparse(sandbox: World) -> None:
    """A few items a cell on average: the walk tests a handful of segments a cell."""
    grid = RayGrid.build(sandbox.segments, sandbox.circles)
    assert grid is not None and grid.items_per_cell < 4 and grid.shape[0] * grid.shape[1] >= 200


def test_a_small_world_far_out_has_a_grid_of_bounded_size() -> None:
    """A millimetre box 1e8 m out: the cells' padding (1e-7 of the coordinates, 10 m
    here) once made a grid of billions of cells; now a few cells no smaller than the
    padding, and its casts are still the reference's."""
    seg = np.array([[1e8, 1e8, 1e8 + 1e-3, 1e8], [1e8, 1e8 + 1e-3, 1e8 + 1e-3, 1e8 + 1e-3],
                    [1e8, 1e8, 1e8, 1e8 + 1e-3], [1e8 + 1e-3, 1e8, 1e8 + 1e-3, 1e8 + 1e-3]])
    grid = RayGrid.build(seg, np.zeros((0, 3)))
    if grid is None:
        pytest.skip("no C compiler: the C cast is not built")
    assert max(grid.shape) <= raycast.MAX_CELLS
    assert grid.shape[0] * grid.shape[1] * grid.items_per_cell <= 64      # a few cells, not millions
    world = World(seg, np.zeros((0, 3)))
    angles = np.linspace(0, 2 * math.pi, 64, endpoint=False)
    origins = np.tile([1e8 + 5e-4, 1e8 + 5e-4], (64, 1))
    assert np.array_equal(world.cast(origins, angles), world.cast_exact(origins, angles))


def _pymunk_cast(world: World, origins: np.ndarray, angles: np.ndarray, length: float) -> np.ndarray:
    space = pymunk.Space()
    body = space.static_body
    space.add(*[pymunk.Segment(body, (s[0], s[1]), (s[2], s[3]), 0.0) for s in world.segments])
    space.add(*[pymunk.Circle(body, c[2], (c[0], c[1])) for c in world.circles])
    out = np.empty(len(angles))
    for i, ((x, y), a) in enumerate(zip(origins, angles, strict=True)):
        hit = space.segment_query_first((x, y), (x + length * math.cos(a), y + length * math.sin(a)), 0.0,
                                        pymunk.ShapeFilter())
        out[i] = math.inf if hit is None else hit.alpha * length
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_the_c_cast_meets_what_pymunk_meets(seed: int) -> None:
    """Random walls and posts, 200 random rays from outside the posts (pymunk meets a
    post at 0 from inside): pymunk's first hit, to 1e-9 m."""
    rng = np.random.default_rng(seed)
    world = _random_world(rng, 15, 5)
    origins = rng.uniform(-12, 12, (200, 2))
    angles = rng.uniform(-math.pi, math.pi, 200)
    c = world.circles
    outside = (np.hypot(origins[:, None, 0] - c[:, 0], origins[:, None, 1] - c[:, 1]) > c[:, 2]).all(axis=1)
    origins, angles = origins[outside], angles[outside]
    _same(_c(world, origins, angles, 40.0), _pymunk_cast(world, origins, angles, 40.0))


def test_the_c_cast_meets_what_pymunk_meets_on_a_ros_map(sandbox: World) -> None:
    rng = np.random.default_rng(7)
    origins = rng.uniform(-3.5, 3.5, (1500, 2))
    angles = rng.uniform(-math.pi, math.pi, 1500)
    _same(_c(sandbox, origins, angles, 40.0), _pymunk_cast(sandbox, origins, angles, 40.0))


def test_world_cast_is_the_c_cast_and_the_lidar_uses_it(sandbox: World) -> None:
    """``World.cast`` gives the reference's figures; so does a lidar turn of a moving
    chair, each beam from its own pose."""
    rng = np.random.default_rng(3)
    origins, angles = _random_rays(rng, sandbox, 1000, span=4.0)
    assert sandbox.cast(origins, angles).tobytes() == sandbox.cast_exact(origins, angles).tobytes()
    assert sandbox.__dict__.get("_ray_grid") is not None

    class Reference:
        def cast(self, origins, angles, max_range=math.inf):
            return sandbox.cast_exact(origins, angles, max_range)

    def pose_at(t: np.ndarray):
        return -0.5 + 0.8 * t, 0.4 + 0.1 * t, 0.3 + 1.5 * t

    lidar = Lidar()
    fast = lidar.samples(sandbox, pose_at, 0.0, None)[1]
    assert np.array_equal(fast, lidar.samples(Reference(), pose_at, 0.0, None)[1])    # type: ignore[arg-type]
    assert (fast > 0).mean() > 0.9


def test_without_the_c_helper_the_world_casts_with_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(raycast, "_lib", False)
    world = World.from_table({"walls": [[5, -1, 5, 5]], "circles": [[3, -3, 0.5]]})
    assert RayGrid.build(world.segments, world.circles) is None
    rng = np.random.default_rng(0)
    origins, angles = _random_rays(rng, world, 200)
    assert world.cast(origins, angles).tobytes() == world.cast_exact(origins, angles).tobytes()
    assert world.__dict__["_ray_grid"] is None


def test_a_world_that_has_cast_pickles_without_its_grid() -> None:
    world = World.from_table({"walls": [[5, -1, 5, 5]]})
    assert world.cast(np.zeros(2), np.zeros(1))[0] == 5.0
    copy = pickle.loads(pickle.dumps(world))
    assert "_ray_grid" not in copy.__dict__ and copy.cast(np.zeros(2), np.zeros(1))[0] == 5.0
