"""The lidar on ``sim://`` and ``simavr://``: ``world=``, ``start=`` and ``lidar=`` on the
URL, ``chair.scan()`` and ``chair.on_scan()``, watched against the plant, on both
backends.

Physics first: the chair stands at the origin facing a wall 3 m ahead (x = 3, from
y = -2 to 2); the S3 sits 0.20 m ahead of the axle (the seed's mount), so a beam at
angle a (the laser frame, counter-clockwise from ahead) meets the wall after
(3 - 0.20) / cos(a) for |a| < atan(2 / 2.8), and nothing at all behind. After a drive
toward it, the beams ahead read the wall from where the plant says the chair stopped,
and the chair never goes through it.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

import wcdrive
from tests.support.board_of import board_of
from wcdrive.errors import WcdriveConnectionError, WcdriveError, WcdriveFaultError
from wcdrive.plant import ChairParams
from wcdrive.plant.lidar import RPLIDAR_S3, SEED_MOUNT

BACKENDS = ("sim://?speed=5&", pytest.param("simavr://?realtime=0&", marks=pytest.mark.simavr))
WALL_X = 3.0
#: five standard deviations of the S3's range noise, and the quarter millimetre
TOLERANCE = 5 * RPLIDAR_S3.range_sigma + 0.00025


@pytest.fixture
def wall(tmp_path: Path) -> Path:
    path = tmp_path / "wall.toml"
    path.write_text(f'name = "wall"\nwalls = [[{WALL_X}, -2.0, {WALL_X}, 2.0]]\n')
    return path


def _angles(scan: wcdrive.plant.lidar.LaserScan) -> np.ndarray:
    return scan.angle_min + np.arange(len(scan.ranges)) * scan.angle_increment


def _board(chair: object) -> object:
    return board_of(chair._session.port)


@pytest.mark.parametrize("base", BACKENDS)
def test_a_standing_chair_scans_the_wall_it_faces(base: str, wall: Path) -> None:
    with wcdrive.connect(f"{base}world={wall}&start=0,0,0&lidar=rplidar_s3") as chair:
        assert chair.has_lidar
        scan = chair.scan(timeout=5.0)
        later = chair.scan(timeout=5.0)
    assert len(scan.ranges) == RPLIDAR_S3.beams == 3240
    assert (scan.scan_time, scan.frame_id) == (pytest.approx(0.1), "laser")
    assert later.stamp > scan.stamp
    a = _angles(scan)
    ahead = np.abs(a) < math.atan2(2.0, WALL_X - SEED_MOUNT.x) - 0.02
    expected = (WALL_X - SEED_MOUNT.x) / np.cos(a[ahead])
    error = scan.ranges[ahead] - expected
    assert ahead.sum() > 600             # 69 of 360 degrees
    assert np.all(np.abs(error) < TOLERANCE), float(np.abs(error).max())
    assert abs(float(error.mean())) < 0.002
    behind = np.abs(a) > math.radians(120)
    assert np.all(np.isinf(scan.ranges[behind]))


@pytest.mark.parametrize("base", BACKENDS)
def test_a_chair_driven_at_the_wall_scans_it_from_where_it_stopped(base: str, wall: Path) -> None:
    """Driven at 0.5 m/s for 12 s (6 m; the wall is 3 m away), the chair meets the wall
    and its wheels stall against it: the current senses show them held at their limit,
    so the firmware latches no fault and stops nothing for the 7 s it pushes (the stall
    timeout is 15 s: docs/safety.md, "Stall timeout"); the chair stands at the wall."""
    front = ChairParams().footprint_ahead_of_axle + ChairParams().length / 2
    seen: list[float] = []
    with wcdrive.connect(f"{base}world={wall}&start=0,0,0&lidar=rplidar_s3") as chair:
        chair.on_scan(lambda s: seen.append(float(s.ranges[np.argmin(np.abs(_angles(s)))])))
        board = _board(chair)
        deadline = time.monotonic() + 60.0
        refused = None
        while board.time < 12.0 and time.monotonic() < deadline:
            try:
                chair.set_velocity(0.5, 0.0)
            except WcdriveFaultError as exc:
                refused = exc
                break
            time.sleep(0.05)
            assert board.pose()[0] + front < WALL_X + 0.02
        stop_at = board.time
        while board.time < stop_at + 1.5:
            time.sleep(0.05)
        x, _, heading = board.pose()
        scan = chair.scan(timeout=5.0)
        faults = chair.faults
        events = chair.events
    assert refused is None and not faults, (faults, events)
    assert not {"STALLED_ON_GRADE", "STALL_TIMEOUT"} & set(events), events
    a = _angles(scan)
    ahead = np.abs(a) < 0.2
    expected = (WALL_X - (x + SEED_MOUNT.x * math.cos(heading))) / np.cos(a[ahead] + heading)
    assert np.all(np.abs(scan.ranges[ahead] - expected) < TOLERANCE)
    assert seen[0] > seen[-1] + 1.0      # the wall came closer as the chair drove
    assert WALL_X - 0.05 < x + front < WALL_X + 0.02    # it drove up to the wall, not through


def test_a_chair_without_a_lidar_says_so() -> None:
    with wcdrive.connect("sim://?speed=5") as chair:
        assert not chair.has_lidar
        with pytest.raises(WcdriveError, match="no lidar"):
            chair.scan()
        with pytest.raises(WcdriveError, match="no lidar"):
            chair.on_scan(print)


@pytest.mark.parametrize(("query", "says"), [
    ("world=nowhere", "no bundled world of that name"),
    ("world=/nonexistent/room.yaml", "cannot read"),
    ("world=furnished_room&start=0,0,0", "overlaps the world"),
    ("start=1,2", "three finite numbers"),
    ("start=1,nan,0", "three finite numbers"),
    ("lidar=ouster", "must be one of rplidar_s3"),
])
def test_a_bad_world_start_or_lidar_is_a_clear_error(query: str, says: str) -> None:
    with pytest.raises(WcdriveConnectionError, match=says):
        wcdrive.connect(f"sim://?{query}")


def test_a_bundled_world_by_name_puts_the_chair_in_it() -> None:
    """The furnished room's east wall is 8 m from its west one; the chair at x = 4
    facing east sees it 3.8 m ahead."""
    with wcdrive.connect("sim://?speed=5&world=furnished_room&start=4.0,1.2,0&lidar=rplidar_s3") as chair:
        scan = chair.scan(timeout=5.0)
    a = _angles(scan)
    assert abs(float(scan.ranges[np.argmin(np.abs(a))]) - (8.0 - 4.0 - SEED_MOUNT.x)) < TOLERANCE
