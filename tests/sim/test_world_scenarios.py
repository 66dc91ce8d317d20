"""A scenario's walls and start pose (``[world]`` map, walls, boxes, circles, start): parsed
with clear errors, the chair placed at the start on both backends, its collisions in
the results; the bundled hospital corridor (a map_server map) and furnished room."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.support.grade import bundled
from wcdrive.firmware import constants as C
from wcdrive.plant.chair import footprint
from wcdrive.plant.params import ChairParams
from wcdrive.plant.rosmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, load_map, save_map
from wcdrive.plant.world import World
from wcdrive.sim import runner, scenario
from wcdrive.sim.report import table, to_json
from wcdrive.sim.scenario import BUNDLED, ScenarioError

DRIVE = '[[segment]]\ncmdvel = [0.4, 0.1]\nduration = 2.0\n'
CORRIDOR = BUNDLED / "worlds" / "hospital_corridor.yaml"
#: The doorway the corridor_doorway scenario drives through (its left and right jambs).
DOOR = (7.05, 7.90)
#: kg: the chair and its spinning wheels and rotors (tests/plant/test_collisions.py)
M_EFF = ChairParams().mass + 2 * ChairParams().wheel_total_inertia / ChairParams().wheel_radius**2


def _write(tmp_path: Path, text: str, name: str = "w") -> str:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'settle_s = 0.5\n{text}\n{DRIVE}')
    return str(path)


def hospital_corridor() -> OccupancyGrid:
    """The bundled hospital map: a corridor 2 m wide (y 0..2) and 16 m long, three rooms
    north of it and two south, walls 0.1 m thick, doorways 0.85 m wide (north at x 2.05,
    7.05 and 12.55; south at 3.0 and 11.0); 5 cm cells, unknown outside."""
    res, x0, y0 = 0.05, -0.5, -4.5
    data = np.full((220, 340), UNKNOWN, dtype=np.int8)

    def paint(xa: float, ya: float, xb: float, yb: float, value: int) -> None:
        rows = slice(round((ya - y0) / res), round((yb - y0) / res))
        data[rows, round((xa - x0) / res):round((xb - x0) / res)] = value

    paint(-0.1, -4.1, 16.1, 6.1, OCCUPIED)
    paint(0.0, 0.0, 16.0, 2.0, FREE)
    for xa, xb in ((0.0, 5.0), (5.1, 10.0), (10.1, 16.0)):
        paint(xa, 2.1, xb, 6.0, FREE)
    for xa, xb in ((0.0, 8.0), (8.1, 16.0)):
        paint(xa, -4.0, xb, -0.1, FREE)
    for xa in (2.05, 7.05, 12.55):
        paint(xa, 2.0, xa + 0.85, 2.1, FREE)
    for xa in (3.0, 11.0):
        paint(xa, -0.1, xa + 0.85, 0.0, FREE)
    return OccupancyGrid(data, res, (x0, y0, 0.0))


def clearance(world: World, poses: np.ndarray, params: ChairParams | None = None) -> float:
    """m: the least distance between the chair's footprint at ``poses`` (n, 3) and the
    world's segments, the footprint not overlapping them (corners to segments, segments'
    ends to the footprint's sides)."""
    corners = np.array(footprint(params or ChairParams()))
    seg = world.segments
    best = math.inf
    for x, y, th in poses:
        c, s = math.cos(th), math.sin(th)
        pts = np.stack((x + c * corners[:, 0] - s * corners[:, 1],
                        y + s * corners[:, 0] + c * corners[:, 1]), axis=1)
        sides = np.concatenate((pts, np.roll(pts, -1, axis=0)), axis=1)
        best = min(best, _point_segment(pts, seg).min(),
                   _point_segment(seg[:, :2], sides).min(), _point_segment(seg[:, 2:], sides).min())
    return best


def _point_segment(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(P, S) distances from points (P, 2) to segments (S, 4)."""
    a, b = segments[None, :, :2], segments[None, :, 2:]
    p = points[:, None, :]
    ab = b - a
    u = np.clip(np.sum((p - a) * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=2), 1e-300), 0.0, 1.0)
    return np.asarray(np.hypot(*np.moveaxis(p - (a + u[..., None] * ab), 2, 0)))


# ---- the bundled worlds -------------------------------------------------------------------
def test_the_bundled_corridor_map_is_the_hospital_layout(tmp_path: Path) -> None:
    grid = load_map(CORRIDOR)
    expected = hospital_corridor()
    assert np.array_equal(grid.data, expected.data)
    assert (grid.resolution, grid.origin) == (0.05, (-0.5, -4.5, 0.0))
    saved = load_map(save_map(expected, tmp_path / "again"))
    assert (tmp_path / "again.pgm").read_bytes() == CORRIDOR.with_suffix(".pgm").read_bytes()
    assert np.array_equal(saved.data, grid.data)


def test_the_corridor_is_2_m_wide_and_its_doorways_0_85_m() -> None:
    world = World.from_grid(load_map(CORRIDOR))
    walls = world.cast(np.array([7.475, 1.0]), np.array([math.pi / 2, -math.pi / 2]))
    assert walls == pytest.approx([1.0 + 4.0, 1.0], abs=1e-9)     # north through the door, into the room
    across = world.cast(np.array([6.0, 1.0]), np.array([math.pi / 2, -math.pi / 2]))
    assert across.sum() == pytest.approx(2.0, abs=1e-9)
    jambs = world.cast(np.array([7.475, 2.05]), np.array([0.0, math.pi]))
    assert jambs.sum() == pytest.approx(DOOR[1] - DOOR[0]) == pytest.approx(0.85)
    assert ChairParams().width == 0.65


# ---- parsing ------------------------------------------------------------------------------
def test_world_walls_and_start_are_parsed(tmp_path: Path) -> None:
    sc = scenario.load(_write(tmp_path, "[world]\nwalls = [[0, -1, 5, -1, 5, 3]]\n"
                                        "boxes = [[3, 1.5, 0.4, 0.4, 45]]\ncircles = [[4, 0, 0.03]]\n"
                                        "start = [1.0, 0.5, 90]\nslope_deg = 2\n"))
    assert sc.world is not None and sc.world.segments.shape == (6, 4) and sc.world.circles.shape == (1, 3)
    assert sc.start == (1.0, 0.5, pytest.approx(math.pi / 2))
    assert sc.terrain.slope_deg == 2.0
    plain = scenario.load(_write(tmp_path, "[world]\nslope_deg = 2\n"))
    assert plain.world is None and plain.start == (0.0, 0.0, 0.0)


def test_a_map_is_relative_to_the_scenario_file(tmp_path: Path) -> None:
    (tmp_path / "maps").mkdir()
    save_map(hospital_corridor(), tmp_path / "maps" / "h")
    sc = scenario.load(_write(tmp_path, '[world]\nmap = "maps/h.yaml"\nstart = [7.475, 0.9, 90]\n'))
    assert sc.world is not None and sc.world.grid is not None
    assert np.array_equal(sc.world.segments, World.from_grid(load_map(CORRIDOR)).segments)


@pytest.mark.parametrize(("text", "message"), [
    ("[world]\nstart = [1, 2]\n", r"\[world\] start is \[x, y, heading_deg\]"),
    ('[world]\nstart = [1, 2, "north"]\n', "start is"),
    ("[world]\nstart = [1, 2, nan]\n", "start is"),
    ("[world]\nstart = 3\n", "start is"),
    ("[world]\nwalls = [[0, 0, 1]]\n", r"\[world\] walls\[0\]: a polyline needs x, y pairs"),
    ("[world]\nwalls = [0, 0, 1, 1]\n", r"\[world\] walls is a list of lists"),
    ("[world]\nwalls = [[0, 0, inf, 1]]\n", r"walls\[0\] must be finite numbers"),
    ("[world]\nboxes = [[1, 1, 0.5]]\n", r"boxes\[0\]: \[cx, cy, width, height\]"),
    ("[world]\ncircles = [[1, 1, -0.1]]\n", r"circles\[0\]: \[x, y, radius > 0\]"),
    ('[world]\nmap = "nowhere.yaml"\n', r"\[world\] .*nowhere.yaml"),
    ("[world]\nmap = 3\n", "map is the path of a map_server YAML"),
    ("[world]\nwalls = [[0.5, -1, 0.5, 1]]\n",
     r"start: the chair's footprint at \(0, 0, 0 deg\) overlaps the world"),
    ("[world]\ncircles = [[0, 0.5, 0.1]]\nstart = [0, 0, 90]\n", "overlaps the world near"),
    ("[world]\nwals = [[1, -1, 1, 1]]\n", r"\[world\]: unknown keys: wals"),
])
def test_world_errors_name_the_field(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        scenario.load(_write(tmp_path, text))


# ---- runs ---------------------------------------------------------------------------------
def test_without_a_world_the_result_has_none_and_no_collision_figures(tmp_path: Path) -> None:
    r = runner.run(scenario.load(_write(tmp_path, "")))
    assert r.world is None
    assert not {"collisions", "first_collision_s", "max_impact_ns", "start_x"} & set(r.metrics())
    assert "world:" not in table(r)


def test_the_start_pose_places_the_chair_and_its_odometry(tmp_path: Path) -> None:
    """The same drive from (0, 0, 0) and from (1, 2, 90 deg): the second's ground truth is
    the first's turned and moved to the start, and so are the odometries' figures."""
    home = runner.run(scenario.load(_write(tmp_path, "")))
    moved = runner.run(scenario.load(_write(tmp_path, "[world]\nstart = [1.0, 2.0, 90]\n", "m")))
    assert moved.world is not None and not moved.world.walled
    assert moved.truth.pose[0] == pytest.approx([1.0, 2.0, math.pi / 2], abs=1e-4)
    hx, hy, hth = home.truth.pose[-1]
    assert moved.truth.pose[-1] == pytest.approx([1.0 - hy, 2.0 + hx, hth + math.pi / 2], abs=1e-6)
    assert np.allclose(moved.odometry.wheel, home.odometry.wheel, atol=1e-6)   # from its own origin
    mh, mm = home.metrics(), moved.metrics()
    assert mm["odom_wheel_x"] == pytest.approx(1.0 - mh["odom_wheel_y"], abs=1e-6)  # type: ignore[operator]
    for key in ("odom_wheel_position_error_m", "odom_gyro_heading_error_deg"):
        assert mm[key] == pytest.approx(mh[key], abs=1e-5)
    assert (mm["start_x"], mm["start_y"], mm["start_heading_deg"]) == (1.0, 2.0, pytest.approx(90.0))
    assert "collisions" not in mm


def test_through_the_doorway_without_touching() -> None:
    """Square to a doorway 0.85 m wide, the chair (0.65 m) drives 3 m through it into the
    room: no collision, no alarm, at least 5 cm clear of the jambs all the way."""
    r = bundled("corridor_doorway", "port")
    assert r.world is not None and r.world.walled
    assert (r.world.collisions, r.world.first_collision_s, r.world.max_impact_ns) == (0, None, 0.0)
    assert r.world.contacts == [] and r.world.contact_s == 0.0
    x, y, _ = r.truth.pose[-1]
    assert y - 0.3 > 2.1 and DOOR[0] < x < DOOR[1]          # the whole chair is in the room
    world = scenario.load("corridor_doorway").world
    assert world is not None
    assert 0.05 < clearance(world, r.truth.pose) < 0.1
    assert not [line for _, line in r.link.events if line.startswith("EVT:FAULT")]
    m = json.loads(to_json([r]))[0]
    assert (m["collisions"], m["first_collision_s"], m["max_impact_ns"]) == (0, None, 0.0)
    assert "world: start (7.475, 0.900, 90.0 deg), 0 collisions" in table(r)


def test_the_clearance_sees_a_touch() -> None:
    world = World.from_table({"walls": [[0.7, -1, 0.7, 1]]})
    assert clearance(world, np.array([[0.0, 0.0, 0.0]])) == pytest.approx(0.0, abs=1e-12)
    assert clearance(world, np.array([[-0.02, 0.0, 0.0]])) == pytest.approx(0.02)


#: The hold's least duty: a held wheel one or two counts past the deadband (the limit
#: parks the chair against the wall under the hold).
HOLD_LEAST = 2 * C.HOLD_GAIN


#: The duty of a wheel held at its current limit (STALL_HELD_OUTPUT: 42).
HELD_DUTY = int(C.STALL_HELD_OUTPUT * C.PWM_SCALE)


def _pushes_then_times_out(r: runner.SimResult, first: float) -> float:
    """No fault and no other stop at the wall: both wheels held at their current limit
    (duty HELD_DUTY from 0.5 s after the impact, but for a tick now and then), one
    ``EVT:STALL_TIMEOUT`` 15 to 16 s after the impact (the stall clock starts once both
    encoders stand, a few ticks after it), then parked under the hold. Returns the
    timeout's time."""
    stops = [(t, line) for t, line in r.link.events if line.startswith(("EVT:FAULT", "EVT:STALL"))]
    assert [line for _, line in stops] == ["EVT:STALL_TIMEOUT"], r.link.events
    at = stops[0][0]
    assert 15.0 < at - first < 16.0
    pushing = r.board.pwm[(r.board.tick_time > first + 0.5) & (r.board.tick_time < at - 0.05)]
    # held; a tick in which a wheel creeps a count is not held: its PID, unbound, asks a
    # little more (its integral was held at the bound), and is held again at the next
    assert np.mean(pushing == HELD_DUTY) > 0.9 and pushing.max() <= 1.6 * HELD_DUTY
    assert np.all(r.board.pwm[r.board.tick_time > at + 1.5] <= HOLD_LEAST)
    return at


def test_into_a_wall_the_chair_pushes_at_its_current_limit_then_times_out() -> None:
    """At 0.5 m/s into the room's east wall, the host asking for 0.5 m/s for 17 s more:
    one collision, the front edge stopped on the wall (axle at 5.0 - 0.7 m); the impact
    at most the chair's momentum (a corner hits first, so the chair turns square and less
    than m v lands at once); the motors, at their current limit, cannot turn the tyres on
    the floor (no slip). The current senses show both motors held at their limit while
    neither encoder counts: no encoder fault (before the senses it latched ENC_STALL_R
    within 0.3 s), the wheels pushed at the motor's full torque and no harder (duty 42),
    until the stall timeout stops the chair 15 s on (``_pushes_then_times_out``); the
    host's further commands are refused."""
    r = bundled("room_wall_bump", "port")
    w = r.world
    assert w is not None and w.collisions == 1 and len(w.contacts) == 1
    first = w.first_collision_s
    assert first is not None and 4.0 < first < 5.0
    assert w.contacts[0].x == pytest.approx(5.0, abs=1e-3)
    assert 0.3 * M_EFF * 0.5 < w.max_impact_ns <= M_EFF * 0.5
    assert r.truth.pose[-1, 0] == pytest.approx(5.0 - 0.7, abs=2e-3)
    assert abs(r.truth.pose[-1, 2]) < math.radians(0.1)        # pushed square to the wall
    _pushes_then_times_out(r, first)
    t = r.truth.step_time
    touching = t > first + 0.1
    assert np.all(np.abs(r.truth.step_contact_speed[touching]) < 0.01)   # neither tyre slips
    assert r.link.line_counts["error"] > 0
    m = json.loads(to_json([r]))[0]
    assert m["collisions"] == 1 and m["first_collision_s"] == pytest.approx(first)
    assert m["max_impact_ns"] == pytest.approx(w.max_impact_ns)
    assert m["contact_records"] == [[pytest.approx(v) for v in (first, w.contacts[0].x, w.contacts[0].y,
                                                                  w.contacts[0].impact)]]
    assert "1 collision, the first at" in table(r)


@pytest.mark.simavr
@pytest.mark.thorough
def test_into_a_wall_on_simavr_as_on_the_port() -> None:
    """The compiled firmware in simavr (no difference from the port on its own inputs)
    drives the same plant into the same wall: the same collision, within 2 ms (the two
    boards' timing differs a little), no fault, the wheels held at their current limit
    and the stall timeout 15 to 16 s after the impact, on both backends, within 0.5 s of
    each other. A 23 s run of simavr (about 22 s of wall time): the thorough depth's;
    tests/firmware/test_stall_timeout.py holds the rule itself on both backends at both
    depths."""
    port, avr = bundled("room_wall_bump", "port"), bundled("room_wall_bump", "simavr")
    assert avr.world is not None and port.world is not None
    assert avr.world.collisions == port.world.collisions == 1
    first = avr.world.first_collision_s
    # both on the plant's 1 ms steps: 2 steps apart at most (4.788 against 4.790 s is
    # 0.002000000000066 s in binary64, past an ``approx`` of 0.002)
    port_first = port.world.first_collision_s
    assert first is not None and port_first is not None
    assert abs(round(first * 1000) - round(port_first * 1000)) <= 2
    assert avr.world.max_impact_ns == pytest.approx(port.world.max_impact_ns, rel=0.02)
    assert _pushes_then_times_out(avr, first) == pytest.approx(_pushes_then_times_out(port, first), abs=0.5)
    assert avr.truth.pose[-1, 0] == pytest.approx(5.0 - 0.7, abs=2e-3)
