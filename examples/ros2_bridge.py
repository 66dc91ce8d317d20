"""A ROS 2 bridge for the chair: ``cmd_vel`` -> ``Wheelchair.set_velocity``, odometry ->
``/odom`` (docs/ros2.md). UNTESTED in this project: ROS 2 is not installable on its
machines; the test suite only compiles this file.

    python3 examples/ros2_bridge.py --ros-args -p url:=sim://     # or /dev/ttyACM0
"""

from __future__ import annotations

import math
import threading
import time

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node

import wcdrive

#: Stop when no cmd_vel came for this long (s); the board's own watchdog is 0.5 s.
CMD_TIMEOUT = 0.3


class WheelchairBridge(Node):
    def __init__(self) -> None:
        super().__init__("wcdrive_bridge")
        url = self.declare_parameter("url", "sim://").value
        self.frame_id = self.declare_parameter("odom_frame", "odom").value
        self.child_frame_id = self.declare_parameter("base_frame", "base_link").value
        self.chair = wcdrive.connect(url)
        self.get_logger().info(f"connected to {url}")
        self._last_cmd = (0.0, 0.0)
        self._last_cmd_at = 0.0
        self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, 10)
        self.odom_pub = self.create_publisher(Odometry, "odom", 10)
        self.create_timer(0.1, self._resend)          # the board needs a command >= 2 Hz
        self._odom_thread = threading.Thread(target=self._publish_odometry, daemon=True)
        self._odom_thread.start()

    def _on_cmd_vel(self, msg: Twist) -> None:
        self._last_cmd = (msg.linear.x, msg.angular.z)
        self._last_cmd_at = time.monotonic()
        self._send()

    def _resend(self) -> None:
        if time.monotonic() - self._last_cmd_at > CMD_TIMEOUT:
            self._last_cmd = (0.0, 0.0)
        self._send()

    def _send(self) -> None:
        try:
            self.chair.set_velocity(*self._last_cmd)
        except wcdrive.WcdriveError as exc:          # link down, e-stop latched, fault
            self.get_logger().warning(str(exc), throttle_duration_sec=1.0)

    def _publish_odometry(self) -> None:
        for est in self.chair.odometry_stream(rate_hz=50.0):
            msg = Odometry()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.header.frame_id = self.frame_id
            msg.child_frame_id = self.child_frame_id
            msg.pose.pose.position.x = est.pose.x
            msg.pose.pose.position.y = est.pose.y
            msg.pose.pose.orientation.z = math.sin(est.pose.theta / 2.0)
            msg.pose.pose.orientation.w = math.cos(est.pose.theta / 2.0)
            msg.pose.covariance = [float(v) for v in est.pose_covariance.ravel()]
            msg.twist.twist.linear.x = est.linear
            msg.twist.twist.angular.z = est.angular
            msg.twist.covariance = [float(v) for v in est.twist_covariance.ravel()]
            self.odom_pub.publish(msg)

    def close(self) -> None:
        self.chair.close()                            # stops the chair


def main() -> None:
    rclpy.init()
    node = WheelchairBridge()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
