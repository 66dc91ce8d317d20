"""``/scan`` from a chair with a lidar (``sim://?world=...&lidar=rplidar_s3``), read by
the independent DDS peer: the S3's 3,240 beams in frame ``laser``, base_link -> laser
in ``/tf_static``, and the beam ahead reading the wall 5 m ahead from where the
odometry says the chair is."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

import wcdrive
from tests.ros2.conftest import fresh_domain, run_peer
from wcdrive.plant.lidar import RPLIDAR_S3, SEED_MOUNT
from wcdrive.ros2.dds.graph import RosNode
from wcdrive.ros2.dds.node import ChairNode, Options

WALL_X = 5.0


def test_a_chair_with_a_lidar_publishes_its_scans(tmp_path: Path) -> None:
    wall = tmp_path / "wall.toml"
    wall.write_text(f"walls = [[{WALL_X}, -3.0, {WALL_X}, 3.0]]\n")
    domain = fresh_domain()
    chair = wcdrive.connect(f"sim://?speed=2&world={wall}&lidar=rplidar_s3")
    node = ChairNode(chair, RosNode("wcdrive", domain=domain), Options())
    try:
        assert "/scan" in node.published
        node.start()
        peer: dict[str, Any] = run_peer(domain, "forward", "--seconds", "3")
    finally:
        node.close()
        chair.close()
    assert peer["counts"]["rt/scan"] >= 5, peer["counts"]
    frame, ranges, increment = peer["scans"][-1]
    assert frame == "laser" and len(ranges) == RPLIDAR_S3.beams
    assert ["base_link", "laser"] in peer["tf_static"]
    ahead = float(ranges[round(math.pi / increment)])
    x = peer["odom"][-1][2]
    assert x > 0.1                                            # the peer drove it
    assert abs(ahead - (WALL_X - SEED_MOUNT.x - x)) < 0.12, (ahead, x)   # 0.3 m/s, scans 0.1 s apart
    assert np.isinf(float(ranges[0]))                         # behind: nothing
