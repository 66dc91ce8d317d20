"""The DDS node's ROS 2 messages, as dicts in each message's field layout (what
``types.build`` takes): stamps, odometry, transforms, wheel joints, diagnostics; those
``wcdrive.ros2.bridge`` already builds for MCAP and Foxglove are its.

Frames follow REP 105: ``odom`` -> ``base_link`` is the odometry's transform; the
wheel joints are ``left_wheel_joint`` and ``right_wheel_joint`` (rad, forward
positive).
"""

from __future__ import annotations

from typing import Any

from wcdrive.ros2 import bridge
from wcdrive.ros2.bridge import BASE_FRAME as BASE_FRAME
from wcdrive.ros2.bridge import ODOM_FRAME as ODOM_FRAME
from wcdrive.ros2.bridge import header, quaternion
from wcdrive.ros2.bridge import joint_state as joint_state
from wcdrive.ros2.bridge import stamp as stamp

IMU_FRAME = bridge.IMU_FRAME
#: diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2


def seconds(time: dict[str, int]) -> float:
    """``builtin_interfaces/msg/Time`` in seconds."""
    return time["sec"] + time["nanosec"] * 1e-9


def odometry(t: float, estimate: Any, frame: str = ODOM_FRAME, child: str = BASE_FRAME) -> dict[str, Any]:
    """``nav_msgs/msg/Odometry`` of an ``OdometryEstimate`` (its 6x6 covariances)."""
    pose = estimate.pose
    return bridge.odometry(t, pose.x, pose.y, pose.theta, estimate.linear, estimate.angular,
                           estimate.pose_covariance, estimate.twist_covariance, frame, child)


def transform(t: float, frame: str, child: str, x: float = 0.0, y: float = 0.0, z: float = 0.0,
              yaw: float = 0.0) -> dict[str, Any]:
    """``geometry_msgs/msg/TransformStamped`` ``frame`` -> ``child``."""
    return {"header": header(t, frame), "child_frame_id": child,
            "transform": {"translation": {"x": x, "y": y, "z": z}, "rotation": quaternion(yaw)}}


def status(name: str, level: int, message: str, hardware_id: str, values: dict[str, Any]
           ) -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticStatus``."""
    return {"level": level, "name": name, "message": message, "hardware_id": hardware_id,
            "values": [{"key": k, "value": str(v)} for k, v in values.items()]}


def diagnostics(t: float, statuses: list[dict[str, Any]]) -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticArray``."""
    return {"header": header(t, ""), "status": statuses}
