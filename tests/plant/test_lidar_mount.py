"""A lidar's mount and driver, physics first: a wall 2.0 m behind the chair and another
1.5 m to its left, seen through a head-down lidar that faces backward (roll 180, yaw
180), as Slamtec's ``rplidar_ros`` and ``sllidar_ros2`` publish its turn, told
``inverted`` or not, binned (``angle_compensate``) or not. The beam whose stated angle
(``angle_min + i * angle_increment``), put through the laser frame's rotation, points
straight back reads 2.0 m less the mount's 0.30 m; the one pointing left 1.5 m less
its 0.10 m; nothing to the right or ahead. Then each driver's own fields, the mirror a
head-down mount makes, and the mount's text form."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wcdrive.plant.lidar import (
    SEED_MOUNT,
    LaserScan,
    Lidar,
    LidarMount,
    configured_lidar,
    lidar_from_table,
    lidar_named,
)
from wcdrive.plant.lidar_driver import LidarDriver
from wcdrive.plant.lidar_mount import parse_mount, quaternion_rpy
from wcdrive.plant.params import ChairFileError, load_chair, load_chair_lidar
from wcdrive.plant.world import World

#: the chair at the origin facing +x (base_link = the world): a wall 2.0 m behind it
#: (x = -2.0) and one 1.5 m to its left (y = 1.5); nothing ahead or to the right
BACK, LEFT = 2.0, 1.5
WALLS = World.from_table({"walls": [[-BACK, -8.0, -BACK, LEFT], [-BACK, LEFT, 8.0, LEFT]]})
#: head down, facing backward, 0.30 m behind the axle, 0.10 m left of it, 0.25 m up
MOUNT_TEXT = "-0.30,0.10,0.25,180,0,180"
#: hand-worked: straight back 2.0 - 0.30, straight left 1.5 - 0.10
WANT_BACK, WANT_LEFT = BACK - 0.30, LEFT - 0.10
TOL = 0.002       # quarter millimetres, and rplidar_ros's stated angles up to 1 deg off


def _still(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros_like(t), np.zeros_like(t), np.zeros_like(t)


def _rotate(q: tuple[float, float, float, float], v: np.ndarray) -> np.ndarray:
    """Vectors ``v`` (N, 3) turned by the unit quaternion ``q`` (x, y, z, w)."""
    u, w = np.array(q[:3]), q[3]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _bearings(scan: LaserScan, mount: LidarMount, shift: float = 0.0) -> np.ndarray:
    """Each beam's direction in base_link (rad), from its stated angle in the laser frame
    (less ``shift``) turned by the laser frame's rotation (what ``/tf_static`` carries);
    level."""
    a = scan.angle_min + np.arange(len(scan.ranges)) * scan.angle_increment - shift
    d = _rotate(mount.laser_rotation, np.column_stack((np.cos(a), np.sin(a), np.zeros_like(a))))
    assert np.allclose(d[:, 2], 0.0, atol=1e-12)
    return np.arctan2(d[:, 1], d[:, 0])


def _toward(scan: LaserScan, mount: LidarMount, bearing: float, shift: float = 0.0) -> tuple[int, float]:
    """The beam pointing nearest ``bearing`` (base_link, rad) and its range."""
    off = np.angle(np.exp(1j * (_bearings(scan, mount, shift) - bearing)))
    i = int(np.argmin(np.abs(off)))
    assert abs(off[i]) < math.radians(1.0)
    return i, float(scan.ranges[i])


CASES = [(driver, told, binned) for driver in ("rplidar_ros", "sllidar_ros2")
         for told in (True, False) for binned in (True, False)]


@pytest.mark.parametrize(("driver", "told", "binned"), CASES)
def test_the_walls_through_a_head_down_backward_mount(driver: str, told: bool, binned: bool) -> None:
    lidar = configured_lidar("rplidar_s3", MOUNT_TEXT, driver, told, binned)
    mount = lidar.mount
    assert (mount.x, mount.y, mount.z) == (-0.30, 0.10, 0.25)
    assert (mount.roll, mount.pitch, mount.yaw) == (math.pi, 0.0, math.pi)
    scan = lidar.scan(WALLS, _still, 0.0)
    shift = 0.0
    if told and not binned:
        # the drivers' own slip: a raw scan's nodes kept in the device's order, but its
        # bounds still pi - last .. pi - first, so every stated angle is off by
        # 360 deg - (first + last) = angle_min + angle_max (0 for a full turn; here the
        # returns span the wall's side only)
        shift = scan.angle_min + scan.angle_max
        assert abs(shift) > math.radians(30)
        assert not math.isclose(_toward(scan, mount, math.pi)[1], WANT_BACK, abs_tol=TOL)
    assert math.isclose(_toward(scan, mount, math.pi, shift)[1], WANT_BACK, abs_tol=TOL)
    assert math.isclose(_toward(scan, mount, math.pi / 2, shift)[1], WANT_LEFT, abs_tol=TOL)
    if binned:                  # a raw scan holds only the samples from the first return to the last
        assert math.isinf(_toward(scan, mount, -math.pi / 2)[1])     # right: nothing
        assert math.isinf(_toward(scan, mount, 0.0)[1])              # ahead: nothing


def test_the_real_stack_s_beam_at_angle_zero_looks_straight_back() -> None:
    """rplidar_ros, ``inverted:=true``, angle_compensate, URDF laser frame yaw pi: the
    laser frame has no roll (the driver un-mirrors the head-down turn), and its angle 0
    is straight back. Worked by hand: angle_min = pi - 359 deg = -179 deg, increment
    359 / 3239 deg, so angle 0 is beam 179 / (359 / 3239) = 1615.0; -90 deg (the laser
    frame's right, base_link's left once turned by pi) is beam 89 / (359 / 3239) = 803.0."""
    lidar = configured_lidar("rplidar_s3", MOUNT_TEXT, "rplidar_ros", True, True)
    assert lidar.mount.tf_roll == 0.0
    assert np.allclose(lidar.mount.laser_rotation, (0.0, 0.0, 1.0, 0.0), atol=1e-15)   # yaw pi only
    scan = lidar.scan(WALLS, _still, 0.0)
    assert math.isclose(math.degrees(scan.angle_min), -179.0, abs_tol=1e-4)
    assert math.isclose(math.degrees(scan.angle_increment), 359.0 / 3239, rel_tol=1e-6)
    assert _toward(scan, lidar.mount, math.pi)[0] == 1615
    assert _toward(scan, lidar.mount, math.pi / 2)[0] == 803
    assert math.isclose(float(scan.ranges[1615]), WANT_BACK, abs_tol=TOL)
    assert math.isclose(float(scan.ranges[803]), WANT_LEFT, abs_tol=TOL)
    assert round(269 / (359 / 3239)) == 2427                                     # laser +90 deg: right
    assert math.isinf(float(scan.ranges[2427]))


@settings(max_examples=40, deadline=None)
@given(yaw=st.floats(-180.0, 180.0), down=st.booleans(), told=st.booleans(), binned=st.booleans(),
       driver=st.sampled_from(("rplidar_ros", "sllidar_ros2")))
def test_any_level_mount_sees_the_walls_where_they_are(yaw: float, down: bool, told: bool, binned: bool,
                                                       driver: str) -> None:
    """Whatever the yaw, head up or down, told or not: the beams put through the laser
    frame find the wall behind at 1.70 m and the one to the left at 1.40 m (a raw scan
    of a driver told ``inverted``: its angles less the drivers' slip, above)."""
    mount = f"-0.30,0.10,0.25,{180 if down else 0},0,{yaw!r}"
    lidar = configured_lidar("rplidar_s3", mount, driver, told, binned)
    scan = lidar.scan(WALLS, _still, 0.0)
    shift = scan.angle_min + scan.angle_max if told and not binned else 0.0     # the drivers' slip
    assert math.isclose(_toward(scan, lidar.mount, math.pi, shift)[1], WANT_BACK, abs_tol=TOL)
    assert math.isclose(_toward(scan, lidar.mount, math.pi / 2, shift)[1], WANT_LEFT, abs_tol=TOL)


@pytest.mark.parametrize("told", [True, False])
def test_each_driver_s_fields(told: bool) -> None:
    """Binned: 3,240 beams either way. sllidar_ros2 states -pi .. pi and range_min 0.05,
    its intensities with their ranges; rplidar_ros states pi - 359 deg .. pi and
    range_min 0.15, and writes each intensity at the index of the node it takes it
    from: when it reverses the ranges (not told ``inverted``) the intensities stay in
    the device's order."""
    scans = {d: configured_lidar("rplidar_s3", MOUNT_TEXT, d, told, True).scan(WALLS, _still, 0.0)
             for d in ("sllidar_ros2", "rplidar_ros")}
    sl, rp = scans["sllidar_ros2"], scans["rplidar_ros"]
    assert len(sl.ranges) == len(rp.ranges) == 3240 and np.array_equal(sl.ranges, rp.ranges)
    assert (sl.angle_min, sl.angle_max) == (float(np.float32(-math.pi)), float(np.float32(math.pi)))
    assert rp.angle_max == float(np.float32(math.pi))
    assert math.isclose(rp.angle_min, math.pi - math.radians(359.0), abs_tol=1e-6)
    assert math.isclose(rp.angle_increment, math.radians(359.0) / 3239, rel_tol=1e-6)
    assert math.isclose(sl.range_min, 0.05, rel_tol=1e-6) and math.isclose(rp.range_min, 0.15, rel_tol=1e-6)
    hit = np.isfinite(sl.ranges)
    assert 0 < hit.sum() < len(hit) and not np.array_equal(hit, hit[::-1])
    assert np.array_equal(sl.intensities, np.where(hit, 47.0, 0.0))
    assert np.array_equal(rp.intensities, np.where(hit if told else hit[::-1], 47.0, 0.0))


def test_without_angle_compensate_the_scan_is_the_samples_from_first_return_to_last() -> None:
    """One beam a sample, 0.1125 deg apart, from the first return to the last; the bounds
    those samples' angles; time_increment the turn's time over the beams less one; a turn
    without a return (no walls) is published whole, bounded by 0 and 359 degrees."""
    for driver in ("sllidar_ros2", "rplidar_ros"):
        lidar = configured_lidar("rplidar_s3", MOUNT_TEXT, driver, True, False)
        scan = lidar.scan(WALLS, _still, 0.0)
        n = len(scan.ranges)
        assert 800 < n < 3200 and np.isfinite(scan.ranges[[0, -1]]).all()
        assert math.isclose(scan.angle_increment, math.radians(0.1125), rel_tol=1e-5)
        assert math.isclose(scan.angle_max - scan.angle_min, (n - 1) * math.radians(0.1125), rel_tol=1e-5)
        assert math.isclose(scan.time_increment, 0.1 / (n - 1), rel_tol=1e-6)
        assert np.array_equal(np.diff(scan.beam_time) > 0, np.ones(n - 1, bool))        # told: device order
        empty = lidar.scan(World(), _still, 0.0)
        assert len(empty.ranges) == 3200 and np.isinf(empty.ranges).all()
        assert math.isclose(empty.angle_min, math.pi - math.radians(359.0), abs_tol=1e-6)


def test_a_head_down_mount_mirrors_the_scan() -> None:
    """Roll 180, the driver not told: the scan of the two walls is the head-up scan of
    the walls mirrored across the chair's axis (y -> -y), beam for beam."""
    mirrored = World.from_table({"walls": [[-BACK, 8.0, -BACK, -LEFT], [-BACK, -LEFT, 8.0, -LEFT]]})
    down = configured_lidar("rplidar_s3", "-0.30,0,0.25,180,0,180").scan(WALLS, _still, 0.0)
    up = configured_lidar("rplidar_s3", "-0.30,0,0.25,0,0,180").scan(mirrored, _still, 0.0)
    assert np.allclose(down.ranges, up.ranges, atol=1e-6, equal_nan=False)
    assert not np.allclose(down.ranges, configured_lidar("rplidar_s3", "-0.30,0,0.25,0,0,180").scan(
        WALLS, _still, 0.0).ranges, atol=1e-6)


def test_the_c_scan_and_the_numpy_reference_agree_for_every_driver() -> None:
    for driver, told, binned in CASES:
        lidar = configured_lidar("rplidar_s3", MOUNT_TEXT, driver, told, binned)
        a = lidar.scan(WALLS, _still, 0.0, np.random.default_rng(5))
        b = lidar.scan_numpy(WALLS, _still, 0.0, np.random.default_rng(5))
        assert a == b, (driver, told, binned)


def test_no_options_is_today_s_lidar() -> None:
    """The seed's mount and sllidar_ros2 with angle_compensate, not told ``inverted``."""
    assert configured_lidar() == lidar_named("rplidar_s3") == Lidar(mount=SEED_MOUNT)
    assert Lidar().driver == LidarDriver("sllidar_ros2", angle_compensate=True)
    assert configured_lidar(mount="0.2,0,0.3,0,0,0") == lidar_named("rplidar_s3")


def test_the_mount_s_rotation_is_the_urdf_s() -> None:
    """``laser_rotation`` is ``Rz(yaw) Ry(pitch) Rx(roll)`` of the device, turned a half
    turn about x when the driver is told; a pitch of 180 is a roll of 180 and a yaw 180
    on, the same rotation and the same scans."""
    q = parse_mount("0,0,0,0,0,90").laser_rotation
    assert np.allclose(q, (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))
    assert np.allclose(parse_mount("0,0,0,180,0,0").laser_rotation, (1.0, 0.0, 0.0, 0.0), atol=1e-15)
    assert np.allclose(parse_mount("0,0,0,180,0,0", driver_inverted=True).laser_rotation,
                       (0.0, 0.0, 0.0, 1.0), atol=1e-15)
    pitched, rolled = parse_mount("0.1,0,0.3,0,180,30"), parse_mount("0.1,0,0.3,180,0,210")
    a, b = quaternion_rpy(0.0, math.pi, math.radians(30)), rolled.laser_rotation
    assert np.allclose(a, b, atol=1e-12) or np.allclose(a, -np.array(b), atol=1e-12)
    assert Lidar(mount=pitched).scan(WALLS, _still, 0.0) == Lidar(mount=rolled).scan(WALLS, _still, 0.0)


@pytest.mark.parametrize(("text", "message"), [
    ("0,0,0.3,0,0", r"six numbers, not 5"),
    ("0,0,0.3,0,0,yes", r"yaw 'yes' is not a number"),
    ("0,0,0.3,90,0,0", r"roll 90 deg: only 0 or 180"),
    ("0,0,0.3,0,10,0", r"pitch 10 deg: only 0 or 180"),
    ("0,nan,0.3,0,0,0", r"y nan is not a finite number"),
])
def test_a_bad_mount_is_named(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_mount(text)


def test_a_chair_file_s_lidar_table() -> None:
    lidar = lidar_from_table({"mount": [-0.3, 0.1, 0.25, 180, 0, 180], "driver": "rplidar_ros",
                              "inverted": True, "angle_compensate": True})
    assert lidar == configured_lidar("rplidar_s3", MOUNT_TEXT, "rplidar_ros", True, True)
    assert lidar_from_table({"mount": MOUNT_TEXT}).mount == parse_mount(MOUNT_TEXT)
    assert lidar_from_table({}) == lidar_named("rplidar_s3")
    for table, message in (({"mount": [1, 2]}, "mount = .* six numbers"),
                           ({"driver": "urg_node"}, "urg_node"),
                           ({"inverted": "yes"}, "inverted = 'yes' is not true or false"),
                           ({"yaw": 3}, r"unknown key 'yaw' \(known: model, mount"),
                           ({"model": "a2"}, "lidar model 'a2': must be one of rplidar_s3")):
        with pytest.raises(ValueError, match=message):
            lidar_from_table(table)
    assert dataclasses.replace(lidar, driver=LidarDriver()).driver.name == "sllidar_ros2"


def test_a_chair_file_s_lidar(tmp_path: Path) -> None:
    """``load_chair_lidar``: the ``[lidar]`` table beside ``[chair]`` (which
    ``load_chair`` reads as before); none without one; a bad one named with its file."""
    path = tmp_path / "chair.toml"
    path.write_text('[chair]\nchair_mass = 95.0\n\n[lidar]\nmount = [-0.3, 0.1, 0.25, 180, 0, 180]\n'
                    'driver = "rplidar_ros"\ninverted = true\n')
    assert load_chair(path).chair_mass == 95.0
    assert load_chair_lidar(path) == configured_lidar("rplidar_s3", MOUNT_TEXT, "rplidar_ros", True, True)
    path.write_text("[chair]\nchair_mass = 95.0\n")
    assert load_chair_lidar(path) is None
    path.write_text('[lidar]\nmount = "0,0,0.3,0,45,0"\n')
    with pytest.raises(ChairFileError, match=r"chair.toml: \[lidar\] lidar mount pitch 45 deg: only 0"):
        load_chair_lidar(path)
    path.write_text("lidar = 3\n")
    with pytest.raises(ChairFileError, match="lidar is not a table"):
        load_chair_lidar(path)
