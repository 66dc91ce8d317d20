"""The DDS node's ROS 2 messages, as dicts in each message's field layout (what
``types.build`` takes): stamps, odometry, transforms, wheel joints, diagnostics; those
``wcdrive.ros2.bridge`` already builds for MCAP and Foxglove are its.

Frames follow REP 105: ``odom`` -> ``base_link`` is the odometry's transform; the
wheel joints are ``left_wheel_joint`` and ``right_wheel_joint`` (rad, forward
positive) unless named otherwise (``left_wheel_names``).

``base_pose``: the odometry of a base frame ``offset`` m ahead of the drive axle's
midpoint (the axle's odometry is the chair's): the odom frame is the axle's odom frame
moved back by ``offset``, so that the base frame starts at the origin; the pose is
that point's, ``(x + offset·(cos θ - 1), y + offset·sin θ, θ)``, and its twist, in the
base frame, ``(v, offset·ω, ω)``: the same forward speed, and the sideways speed of a
point ahead of the axle when the chair turns. The covariances go through the same maps
(``J Σ Jᵀ``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wcdrive.protocol.codec import ExtendedTelemetry
from wcdrive.protocol.spec import PROFILES
from wcdrive.ros2 import bridge
from wcdrive.ros2.bridge import BASE_FRAME as BASE_FRAME
from wcdrive.ros2.bridge import ODOM_FRAME as ODOM_FRAME
from wcdrive.ros2.bridge import header, quaternion
from wcdrive.ros2.bridge import stamp as stamp

IMU_FRAME = bridge.IMU_FRAME
#: The wheels' joints when no names are given.
WHEEL_JOINTS = bridge.WHEEL_JOINTS
#: diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2


def seconds(time: dict[str, int]) -> float:
    """``builtin_interfaces/msg/Time`` in seconds."""
    return time["sec"] + time["nanosec"] * 1e-9


def base_pose(x: float, y: float, theta: float, linear: float, angular: float, offset: float
              ) -> tuple[float, float, float, float, float, float]:
    """(x, y, θ, forward speed, sideways speed, yaw rate) of the base frame ``offset`` m
    ahead of the axle whose odometry is ``x, y, theta, linear, angular`` (module
    docstring)."""
    c, s = math.cos(theta), math.sin(theta)
    return x + offset * (c - 1.0), y + offset * s, theta, linear, offset * angular, angular


def _moved(covariance: Any, row: int, column: int, value: float) -> np.ndarray:
    """``J Σ Jᵀ`` for the identity ``J`` with ``J[row, column] = value``."""
    jacobian = np.eye(6)
    jacobian[row, column] = value
    sigma = np.asarray(covariance, dtype=float).reshape(6, 6)
    return np.asarray(jacobian @ sigma @ jacobian.T)


def odometry(t: float, estimate: Any, frame: str = ODOM_FRAME, child: str = BASE_FRAME,
             offset: float = 0.0, pose_diagonal: tuple[float, ...] | None = None,
             twist_diagonal: tuple[float, ...] | None = None) -> dict[str, Any]:
    """``nav_msgs/msg/Odometry`` of an ``OdometryEstimate``: its 6x6 covariances, or the
    fixed diagonals given (as diff_drive_controller's ``pose_covariance_diagonal``);
    for a base frame ``offset`` m ahead of the axle (``base_pose``)."""
    pose = estimate.pose
    x, y, theta, vx, vy, wz = base_pose(pose.x, pose.y, pose.theta, estimate.linear, estimate.angular,
                                        offset)
    pose_cov, twist_cov = estimate.pose_covariance, estimate.twist_covariance
    if offset:
        pose_cov = _moved(_moved(pose_cov, 0, 5, -offset * math.sin(theta)), 1, 5, offset * math.cos(theta))
        twist_cov = _moved(twist_cov, 1, 5, offset)
    if pose_diagonal is not None:
        pose_cov = np.diag(np.asarray(pose_diagonal, dtype=float))
    if twist_diagonal is not None:
        twist_cov = np.diag(np.asarray(twist_diagonal, dtype=float))
    message = bridge.odometry(t, x, y, theta, vx, wz, pose_cov, twist_cov, frame, child)
    message["twist"]["twist"]["linear"]["y"] = vy
    return message


def joint_state(t: float, positions: tuple[float, float], velocities: tuple[float, float],
                frame: str = BASE_FRAME, left: tuple[str, ...] = (WHEEL_JOINTS[0],),
                right: tuple[str, ...] = (WHEEL_JOINTS[1],)) -> dict[str, Any]:
    """``sensor_msgs/msg/JointState`` of the two wheels (rad, rad/s, forward positive):
    ``positions`` and ``velocities`` are (left, right); each name of ``left`` gets the
    left wheel's, each of ``right`` the right's (diff_drive_controller's
    ``left_wheel_names``, ``right_wheel_names``)."""
    names = [*left, *right]
    sides = [0] * len(left) + [1] * len(right)
    return {"header": header(t, frame), "name": names,
            "position": [float(positions[i]) for i in sides],
            "velocity": [float(velocities[i]) for i in sides], "effort": []}


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


def motor_heat(tlm: ExtendedTelemetry, hardware_id: str) -> dict[str, Any]:
    """``wcdrive: motor heat``, from the board's TLM: WARN while its thermal rollback
    lowers the current and speed limits (TLM ``state`` bit 6), ERROR once a winding's
    cut-off fault (``OVERHEAT_L``/``_R``) is latched, else OK."""
    cut = [name for name in tlm.fault_names if name.startswith("OVERHEAT")]
    if cut:
        level, message = ERROR, "cut off: " + ", ".join(cut)
    elif tlm.thermal_rollback:
        level, message = WARN, "thermal rollback: current and speed limits lowered"
    else:
        level, message = OK, "ok"
    return status("wcdrive: motor heat", level, message, hardware_id,
                  {"thermal_rollback": tlm.thermal_rollback, "cut_off": ",".join(cut)})


def battery(tlm: ExtendedTelemetry, hardware_id: str) -> dict[str, Any]:
    """``wcdrive: battery``, from the board's TLM: the supply it measures (filtered, V);
    WARN while its low-battery rollback lowers the top speed (TLM ``state`` bit 7),
    ERROR once the cut-off fault (``UNDERVOLT``) is latched, else OK."""
    volts = "" if tlm.supply_v is None else f"{tlm.supply_v:.1f}"
    if "UNDERVOLT" in tlm.fault_names:
        level, message = ERROR, f"cut off: the supply at {volts} V"
    elif tlm.battery_low:
        level, message = WARN, f"low: {volts} V, top speed lowered"
    else:
        level, message = OK, f"{volts} V" if volts else "not measured"
    return status("wcdrive: battery", level, message, hardware_id,
                  {"supply_v": volts, "battery_low": tlm.battery_low})


def drive_profile(tlm: ExtendedTelemetry, hardware_id: str) -> dict[str, Any]:
    """``wcdrive: drive profile``, from the board's TLM (``state`` bits 8 and 9): the
    profile in force by number and by its preset's name (OK: a profile is a setting, not
    a condition). The preset's limits are what the profile started as: ``set:`` may have
    changed them on the board (``get:`` reads them)."""
    number = tlm.drive_profile or 0
    preset = PROFILES[number]
    return status("wcdrive: drive profile", OK, f"profile {number} ({preset.name})", hardware_id,
                  {"profile": number, "name": preset.name})


def diagnostics(t: float, statuses: list[dict[str, Any]]) -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticArray``."""
    return {"header": header(t, ""), "status": statuses}
