"""The bridge's ROS 2 messages, as dicts in each message's field layout (what
``types.build`` takes): stamps, odometry, transforms, wheel joints, diagnostics.

Frames follow REP 105: ``odom`` -> ``base_link`` is the odometry's transform; the
wheel joints are ``left_wheel_joint`` and ``right_wheel_joint`` (rad, forward
positive).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

ODOM_FRAME, BASE_FRAME, IMU_FRAME = "odom", "base_link", "imu_link"
WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")
#: diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2


def stamp(seconds: float) -> dict[str, int]:
    """``builtin_interfaces/msg/Time`` of ``seconds``."""
    ns = round(seconds * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def seconds(time: dict[str, int]) -> float:
    """``builtin_interfaces/msg/Time`` in seconds."""
    return time["sec"] + time["nanosec"] * 1e-9


def header(t: float, frame: str) -> dict[str, Any]:
    """A ``std_msgs/msg/Header`` stamped ``t`` seconds in ``frame``."""
    return {"stamp": stamp(t), "frame_id": frame}


def quaternion(yaw: float) -> dict[str, float]:
    """A ``geometry_msgs/msg/Quaternion`` turned ``yaw`` rad about z."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(0.5 * yaw), "w": math.cos(0.5 * yaw)}


def _covariance(matrix: Any) -> list[float]:
    if matrix is None:
        return [0.0] * 36
    return [float(v) for v in np.asarray(matrix, dtype=float).reshape(-1)]


def odometry(t: float, estimate: Any, frame: str = ODOM_FRAME, child: str = BASE_FRAME) -> dict[str, Any]:
    """``nav_msgs/msg/Odometry`` of an ``OdometryEstimate`` (its 6x6 covariances)."""
    pose = estimate.pose
    return {"header": header(t, frame), "child_frame_id": child,
            "pose": {"pose": {"position": {"x": pose.x, "y": pose.y, "z": 0.0},
                              "orientation": quaternion(pose.theta)},
                     "covariance": _covariance(estimate.pose_covariance)},
            "twist": {"twist": {"linear": {"x": estimate.linear, "y": 0.0, "z": 0.0},
                                "angular": {"x": 0.0, "y": 0.0, "z": estimate.angular}},
                      "covariance": _covariance(estimate.twist_covariance)}}


def transform(t: float, frame: str, child: str, x: float = 0.0, y: float = 0.0, z: float = 0.0,
              yaw: float = 0.0) -> dict[str, Any]:
    """``geometry_msgs/msg/TransformStamped`` ``frame`` -> ``child``."""
    return {"header": header(t, frame), "child_frame_id": child,
            "transform": {"translation": {"x": x, "y": y, "z": z}, "rotation": quaternion(yaw)}}


def joint_state(t: float, positions: tuple[float, float], velocities: tuple[float, float],
                frame: str = BASE_FRAME) -> dict[str, Any]:
    """``sensor_msgs/msg/JointState`` of the two wheels."""
    return {"header": header(t, frame), "name": list(WHEEL_JOINTS),
            "position": [float(p) for p in positions], "velocity": [float(v) for v in velocities],
            "effort": []}


def status(name: str, level: int, message: str, hardware_id: str, values: dict[str, Any]
           ) -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticStatus``."""
    return {"level": level, "name": name, "message": message, "hardware_id": hardware_id,
            "values": [{"key": k, "value": str(v)} for k, v in values.items()]}


def diagnostics(t: float, statuses: list[dict[str, Any]]) -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticArray``."""
    return {"header": header(t, ""), "status": statuses}
