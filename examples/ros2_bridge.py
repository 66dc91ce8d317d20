"""A ROS 2 node for the chair without ROS: what ``wcdrive ros2`` does, as library
calls (docs/ros2.md). It joins ``ROS_DOMAIN_ID`` on this host only, publishes
``/odom``, ``/tf``, ``/joint_states``, ``/imu`` (simulated chairs), ``/diagnostics``,
and drives the chair from ``/cmd_vel`` (``geometry_msgs/msg/TwistStamped``).

    python3 examples/ros2_bridge.py sim:// 30        # URL, seconds (default: until Ctrl-C)
    # then, beside a ROS 2 Jazzy install on this host:
    # ros2 topic echo /odom
"""

from __future__ import annotations

import sys
import time

import wcdrive
from wcdrive.ros2.dds.graph import RosNode
from wcdrive.ros2.dds.node import ChairNode, ImuTap, Options


def main(url: str = "sim://", seconds: float | None = None) -> None:
    ros = RosNode("wcdrive")                       # fails here, clearly, if DDS cannot start
    tap = ImuTap()                                 # the simulated board's gyro -> /imu
    with wcdrive.connect(url, ros=tap) as chair:
        node = ChairNode(chair, ros, Options(), imu=tap).start()
        try:
            end = None if seconds is None else time.monotonic() + seconds
            while end is None or time.monotonic() < end:
                time.sleep(0.1)
        except KeyboardInterrupt:
            pass
        finally:
            node.close()                           # stops the chair, leaves the graph
            print("cmd_vel:", dict(node.gate.counts))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "sim://",
         float(sys.argv[2]) if len(sys.argv) > 2 else None)
