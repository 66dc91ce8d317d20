"""docs/ros2.md's topic table says what the node does: each row's type, QoS and RIHS01
hash are the node's (``TOPICS``, ``qos``, rosbags' Jazzy store), and every topic of
the node has its row."""

from __future__ import annotations

import re
from pathlib import Path

from rosbags.typesys import Stores, get_typestore

from wcdrive.ros2.dds import qos
from wcdrive.ros2.dds.graph import ENTITIES_INFO
from wcdrive.ros2.dds.node import TOPICS

PAGE = Path(__file__).resolve().parents[2] / "docs" / "ros2.md"
ROW = re.compile(r"^\| `([^`]+)`(?: \(([^)]*)\))? \| (pub|sub) \| `([^`]+)` \| ([^|]+) \| [^|]+ "
                 r"\| `(RIHS01_\w+)` \|$", re.M)


def test_the_topic_table_is_the_nodes() -> None:
    rows = ROW.findall(PAGE.read_text())
    store = get_typestore(Stores.ROS2_JAZZY)
    documented = {}
    for name, note, direction, msgtype, profile, digest in rows:
        assert digest == store.hash_rihs01(msgtype), (name, msgtype)
        documented[(name, note, direction)] = (msgtype, profile.strip())
    expected = {(t.name, "", t.direction): (t.msgtype, t.live.describe()) for t in TOPICS}
    expected[("/cmd_vel", "`--twist`", "sub")] = ("geometry_msgs/msg/Twist", qos.COMMAND.describe())
    expected[("ros_discovery_info", "no `rt/`", "pub")] = (ENTITIES_INFO, qos.DISCOVERY.describe())
    assert documented == expected
