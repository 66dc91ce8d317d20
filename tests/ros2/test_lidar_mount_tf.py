"""``/tf_static``'s base_link -> laser is the lidar's mount: its translation, and as a
quaternion the laser frame's rotation (``LidarMount.laser_rotation``: the device's
``Rz(yaw) Ry(pitch) Rx(roll)``, a half turn about x less when the driver is told
``inverted``), for a chair whose lidar was set on the URL. The node publishes into a
recording stand-in for the ROS graph."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import wcdrive
from wcdrive.plant.lidar_mount import parse_mount
from wcdrive.ros2.dds.node import ChairNode, Options


class _Recorder:
    """A publisher or a subscription of the stand-in graph."""

    def __init__(self) -> None:
        self.messages: list[Any] = []

    def publish(self, message: Any) -> None:
        self.messages.append(message)

    def take(self, N: int = 1) -> list[Any]:
        return []


class _Graph:
    """What ``ChairNode`` asks of a ``RosNode``: its name and namespace, publishers and
    subscriptions."""

    name, namespace = "wcdrive", "/"

    def __init__(self) -> None:
        self.topics: dict[str, _Recorder] = {}

    def publisher(self, topic: str, msgtype: str, profile: Any) -> _Recorder:
        return self.topics.setdefault(topic, _Recorder())

    def subscription(self, topic: str, msgtype: str, profile: Any) -> _Recorder:
        return _Recorder()

    def close(self) -> None:
        pass


@pytest.mark.parametrize(("mount", "told"), [("-0.30,0.10,0.25,180,0,180", True),
                                             ("-0.30,0.10,0.25,180,0,180", False),
                                             ("0.35,-0.05,0.6,0,0,90", False),
                                             ("0.1,0,0.3,0,180,30", True)])
def test_tf_static_is_the_mount(tmp_path: Path, mount: str, told: bool) -> None:
    wall = tmp_path / "wall.toml"
    wall.write_text("walls = [[-2.0, -3.0, -2.0, 3.0]]\n")
    flag = "true" if told else "false"
    graph = _Graph()
    with wcdrive.connect(f"sim://?speed=5&world={wall}&lidar=rplidar_s3&lidar_mount={mount}"
                         f"&lidar_inverted={flag}") as chair:
        node = ChairNode(chair, graph, Options())   # type: ignore[arg-type]
        node.start()
        node.close()
    (message,) = graph.topics["/tf_static"].messages
    (laser,) = [t for t in message["transforms"] if t["child_frame_id"] == "laser"]
    assert laser["header"]["frame_id"] == "base_link"
    want = parse_mount(mount, told)
    t, r = laser["transform"]["translation"], laser["transform"]["rotation"]
    assert (t["x"], t["y"], t["z"]) == (want.x, want.y, want.z)
    q = np.array([r["x"], r["y"], r["z"], r["w"]])
    w = np.array(want.laser_rotation)
    assert np.allclose(q, w, atol=1e-12) or np.allclose(q, -w, atol=1e-12), (q, w)
    # head down and not told: the frame keeps the roll (x axis forward-back, z down)
    assert (abs(float(q[0])) + abs(float(q[1])) > 0.5) == (want.tf_roll == math.pi)
