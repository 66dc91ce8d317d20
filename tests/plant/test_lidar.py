"""The RPLidar S3 model, physics first: in a room whose walls are at known distances
each beam reads the distance along its published angle; a chair driving at 1 m/s
gives the distortion a turn of 0.1 s makes, worked out by hand; the published fields
are the driver's (3,240 beams, -pi to pi, 0.05 m to 40 m); the noise has the stated
sigma on the device's quarter-millimetre grid; no return is +inf; the mount's offset,
yaw and a head-down mount land where they should."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wcdrive.plant.lidar import RPLIDAR_S3, Lidar, LidarMount
from wcdrive.plant.world import World

#: walls at x = 5 (front), x = -5 (back), y = 3 (left), y = -2 (right)
ROOM = World.from_table({"walls": [[5, -2, 5, 3, -5, 3, -5, -2, 5, -2]]})


def _still(x: float = 0.0, y: float = 0.0, heading: float = 0.0):
    def pose_at(t: np.ndarray):
        return np.full_like(t, x), np.full_like(t, y), np.full_like(t, heading)
    return pose_at


def _at(scan, angle: float) -> float:
    """The range of the published beam nearest ``angle`` (laser frame)."""
    k = round((angle - scan.angle_min) / scan.angle_increment)
    return float(scan.ranges[k])


def test_the_driver_s_fields() -> None:
    """DenseBoost at 10 Hz: 3,200 samples a turn, multiple int(3200/360 + 1) = 9, so
    3,240 beams; -pi to pi; time_increment 0.1 / 3239 s; stamped at the turn's start."""
    scan = Lidar().scan(ROOM, _still(), t0=12.5)
    assert RPLIDAR_S3.samples == 3200 and len(scan.ranges) == len(scan.intensities) == 3240
    assert math.isclose(scan.angle_min, -math.pi, abs_tol=1e-6)
    assert math.isclose(scan.angle_max, math.pi, abs_tol=1e-6)
    assert math.isclose(scan.angle_increment, 2 * math.pi / 3239, rel_tol=1e-6)
    assert math.isclose(scan.time_increment, 0.1 / 3239, rel_tol=1e-6) and math.isclose(scan.scan_time, 0.1,
                                                                                      rel_tol=1e-6)
    assert scan.stamp == 12.5 and scan.frame_id == "laser"
    assert math.isclose(scan.range_min, 0.05, rel_tol=1e-6) and scan.range_max == 40.0
    assert scan.ranges.dtype == np.float32


def test_each_beam_reads_the_wall_along_its_angle() -> None:
    """From the room's origin at rest: 5 m ahead and behind, 3 m left, 2 m right; and at
    every angle the distance to the rectangle, within the driver's one-bin angle rule
    (0.11 deg: under 2 cm at these distances but near the corners)."""
    scan = Lidar().scan(ROOM, _still(), t0=0.0)
    for angle, want in ((0.0, 5.0), (math.pi / 2, 3.0), (-math.pi / 2, 2.0), (math.pi - 0.01, 5.0)):
        assert math.isclose(_at(scan, angle), want / abs(math.cos(angle)) if angle in (0.0, math.pi - 0.01)
                            else want, abs_tol=0.002), angle
    angles = scan.angle_min + np.arange(len(scan.ranges)) * scan.angle_increment
    exact = ROOM.cast(np.zeros(2), angles)
    corners = np.degrees(np.abs(np.arctan2(np.sin(angles), np.cos(angles))))
    away = np.array([min(abs(c - d) for d in (30.96, 21.80, 149.04, 158.20)) > 1.0 for c in corners])
    assert np.abs(scan.ranges - exact)[away].max() < 0.02


def test_a_moving_chair_distorts_the_scan_as_a_turn_takes_time() -> None:
    """At 1 m/s along x: the device's front sample (device angle 180 deg, sample 1,600,
    0.05 s into the turn) reads 5 - 0.05 m; behind, its first sample (t0) reads 5 m
    and its last (0.1 s on) 5.1 m. Published reversed: beam 0 is the last sample."""
    def moving(t: np.ndarray):
        return t * 1.0, np.zeros_like(t), np.zeros_like(t)
    scan = Lidar().scan(ROOM, moving, t0=0.0)
    assert math.isclose(_at(scan, 0.0), 4.95, abs_tol=0.0005)
    assert math.isclose(float(scan.ranges[-1]), 5.0, abs_tol=0.0005)          # the first sample
    assert math.isclose(float(scan.ranges[0]), 5.0 + 0.1 * 3199 / 3200, abs_tol=0.0005)
    assert scan.beam_time[0] > scan.beam_time[-1]


def test_noise_and_the_quarter_millimetre() -> None:
    rng = np.random.default_rng(3)
    lidar = Lidar()
    front = []
    for n in range(40):
        scan = lidar.scan(ROOM, _still(), t0=0.1 * n, rng=rng)
        k = round((0.0 - scan.angle_min) / scan.angle_increment)
        angles = scan.angle_min + np.arange(k - 20, k + 20) * scan.angle_increment
        front += (scan.ranges[k - 20:k + 20] - ROOM.cast(np.zeros(2), angles)).tolist()
        q = scan.ranges.astype(np.float64) * 4000.0
        assert np.abs(q - np.round(q)).max() < 0.01
    assert 0.008 < float(np.std(front)) < 0.012 and abs(float(np.mean(front))) < 0.002


@pytest.mark.parametrize(("table", "x"), [({}, 0.0), ({"walls": [[41, -50, 41, 50]]}, 0.0),
                                          ({"circles": [[0.02, 0, 0.01]]}, 0.0)])
def test_no_return_is_inf(table: dict, x: float) -> None:
    """Nothing there, a wall past 40 m, an object closer than 5 cm."""
    scan = Lidar().scan(World.from_table(table), _still(x), t0=0.0)
    assert np.isinf(_at(scan, 0.0)) and np.count_nonzero(scan.intensities[np.isinf(scan.ranges)]) == 0


def test_the_mount() -> None:
    """0.3 m ahead of the base: 4.7 m to the front wall. Turned 90 deg: its 0 looks left
    (3 m). Head down with the driver told (``inverted``): the same readings, no roll in
    /tf_static; head down and the driver not told: mirrored (left reads the right
    wall), and /tf_static rolls the laser frame by pi to undo it."""
    ahead = Lidar(mount=LidarMount(x=0.3)).scan(ROOM, _still(), 0.0)
    assert math.isclose(_at(ahead, 0.0), 4.7, abs_tol=0.002)
    assert math.isclose(_at(Lidar(mount=LidarMount(yaw_deg=90)).scan(ROOM, _still(), 0.0), 0.0), 3.0,
                        abs_tol=0.002)
    told_mount = LidarMount(inverted=True, driver_inverted=True)
    told = Lidar(mount=told_mount).scan(ROOM, _still(), 0.0)
    assert math.isclose(_at(told, math.pi / 2), 3.0, abs_tol=0.002) and told_mount.tf_roll == 0.0
    mount = LidarMount(inverted=True)
    untold = Lidar(mount=mount).scan(ROOM, _still(), 0.0)
    assert math.isclose(_at(untold, math.pi / 2), 2.0, abs_tol=0.002) and mount.tf_roll == math.pi
    turned = Lidar().scan(ROOM, _still(heading=math.pi / 2), 0.0)
    assert math.isclose(_at(turned, 0.0), 3.0, abs_tol=0.002)             # the chair faces the left wall
