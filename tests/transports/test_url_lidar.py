"""The lidar's mount and driver on a ``wcsim://`` (``sim://``) URL: ``lidar_mount``,
``lidar_driver``, ``lidar_inverted`` and ``lidar_angle_compensate`` give the lidar
``wcdrive.plant.lidar.configured_lidar`` builds; a bad value is a ``SerialException``
naming it; and a live chair's scan through a head-down, backward mount reads the wall
behind it where it is."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import serial

import wcdrive
from wcdrive.plant.lidar import configured_lidar, lidar_named
from wcdrive.transports.urlhandler import protocol_wcsim
from wcdrive.transports.urlhandler.board_serial import placed_lidar, url_options

MOUNT = "-0.30,0.10,0.25,180,0,180"


def _lidar(query: str):
    _, options, _ = url_options(f"wcsim://?{query}", "wcsim", protocol_wcsim.USAGE, protocol_wcsim.OPTIONS)
    return placed_lidar("wcsim", options)


def test_the_options_give_the_configured_lidar() -> None:
    assert _lidar("") is None
    assert _lidar("lidar=rplidar_s3") == lidar_named("rplidar_s3")
    lidar = _lidar(f"lidar=rplidar_s3&lidar_mount={MOUNT}&lidar_driver=rplidar_ros&lidar_inverted=true"
                   "&lidar_angle_compensate=false")
    assert lidar == configured_lidar("rplidar_s3", MOUNT, "rplidar_ros", True, False)
    assert (lidar.mount.x, lidar.mount.yaw, lidar.mount.roll) == (-0.30, math.pi, math.pi)
    assert lidar.mount.driver_inverted and lidar.driver.name == "rplidar_ros"
    assert not lidar.driver.angle_compensate
    told = _lidar("lidar=rplidar_s3&lidar_inverted=1")
    assert told.mount.driver_inverted and told.mount.x == 0.20 and told.driver.name == "sllidar_ros2"


@pytest.mark.parametrize(("query", "message"), [
    ("lidar=rplidar_s3&lidar_mount=0,0,0.3", r"lidar_mount='0,0,0.3': .*six numbers, not 3"),
    ("lidar=rplidar_s3&lidar_mount=0,0,0.3,45,0,0", r"lidar_mount=.*roll 45 deg: only 0 or 180"),
    ("lidar=rplidar_s3&lidar_mount=0,0,0.3,0,0,west", r"yaw 'west' is not a number"),
    ("lidar=rplidar_s3&lidar_driver=urg_node",
     r"lidar_driver='urg_node': must be one of sllidar_ros2, rplidar_ros"),
    ("lidar=rplidar_s3&lidar_inverted=yes", r"lidar_inverted='yes': 'yes' is not true or false"),
    ("lidar=rplidar_s3&lidar_angle_compensate=2", r"lidar_angle_compensate='2': '2' is not true or false"),
    ("lidar_mount=0,0,0.3,0,0,0&lidar_driver=rplidar_ros",
     r"lidar_mount, lidar_driver needs lidar=rplidar_s3"),
])
def test_a_bad_value_is_named(query: str, message: str) -> None:
    with pytest.raises(serial.SerialException, match=message):
        _lidar(query)


def test_a_live_chair_s_scan_through_the_mount(tmp_path: Path) -> None:
    """The real stack's lidar (rplidar_ros, ``inverted:=true``, head down, facing back,
    0.30 m behind the axle) with a wall 2.0 m behind the chair: the beam at laser angle
    0 (straight back) reads 1.70 m, 3,240 beams, range_min 0.15."""
    wall = tmp_path / "wall.toml"
    wall.write_text("walls = [[-2.0, -3.0, -2.0, 3.0]]\n")
    url = (f"sim://?speed=5&world={wall}&lidar=rplidar_s3&lidar_mount={MOUNT}&lidar_driver=rplidar_ros"
           "&lidar_inverted=true")
    with wcdrive.connect(url) as chair:
        assert chair.lidar == configured_lidar("rplidar_s3", MOUNT, "rplidar_ros", True, True)
        scan = chair.scan(timeout=2.0)
    assert len(scan.ranges) == 3240 and math.isclose(scan.range_min, 0.15, rel_tol=1e-6)
    back = round(-scan.angle_min / scan.angle_increment)
    assert back == 1615 and abs(float(scan.ranges[back]) - 1.70) < 0.04        # 10 mm noise, 4 sigma
    left = round((math.pi / 2 - scan.angle_min) / scan.angle_increment)      # the laser frame's left
    assert np.isinf(scan.ranges[left])                                       # (base_link's right): nothing


def test_a_chair_file_s_lidar_table(tmp_path: Path) -> None:
    """``chair=`` with a ``[lidar]`` table gives the board that lidar; ``lidar_*`` on the
    URL replace its keys one by one; ``lidar=`` replaces it whole; a bad table is named."""
    path = tmp_path / "chair.toml"
    path.write_text(f'[chair]\nchair_mass = 95.0\n\n[lidar]\nmount = "{MOUNT}"\ndriver = "rplidar_ros"\n'
                    "inverted = true\n")
    from_file = configured_lidar("rplidar_s3", MOUNT, "rplidar_ros", True, True)
    assert _lidar(f"chair={path}") is None        # url_options alone: no URL to read the file from
    _, options, _ = url_options(f"wcsim://?chair={path}&lidar_inverted=false", "wcsim", protocol_wcsim.USAGE,
                                protocol_wcsim.OPTIONS)
    assert placed_lidar("wcsim", options, f"wcsim://?chair={path}") == configured_lidar(
        "rplidar_s3", MOUNT, "rplidar_ros", False, True)
    port = serial.serial_for_url(f"wcsim://?chair={path}&speed=5")
    try:
        assert port.board.lidar is not None and port.board.lidar.lidar == from_file
        assert port.board.plant.p.chair_mass == 95.0
    finally:
        port.close()
    port = serial.serial_for_url(f"wcsim://?chair={path}&speed=5&lidar=rplidar_s3")
    try:
        assert port.board.lidar is not None and port.board.lidar.lidar == lidar_named("rplidar_s3")
    finally:
        port.close()
    path.write_text('[chair]\n\n[lidar]\ndriver = "urg_node"\n')
    with pytest.raises(serial.SerialException, match=r"wcsim://: chair=: .*chair.toml: \[lidar\] .*urg_node"):
        serial.serial_for_url(f"wcsim://?chair={path}")
