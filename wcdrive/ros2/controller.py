"""The bridge's ROS parameters: diff_drive_controller's names where the bridge does what
that controller does, and the bridge's own for the rest. Pure: no I/O.

``PARAMETERS`` lists every name the bridge's node takes, with its type, default, who
defines it and what the bridge does with it:

- diff_drive_controller (ros2_controllers, jazzy branch,
  ``diff_drive_controller/src/diff_drive_controller_parameter.yaml``): the frames
  (``odom_frame_id``, ``base_frame_id``, ``tf_frame_prefix_enable``,
  ``tf_frame_prefix``: the frames get the prefix, or the node's namespace, as
  ``on_configure`` builds it), ``enable_odom_tf``, ``left_wheel_names`` and
  ``right_wheel_names`` (the joints of ``/joint_states``, each side's wheel's angle
  and speed under each of its names), ``cmd_vel_timeout``, ``publish_rate`` (``/odom``
  and ``/tf`` at most this often), ``pose_covariance_diagonal`` and
  ``twist_covariance_diagonal`` (``/odom``'s covariances, fixed, instead of the chair's
  own estimate), and every ``linear.x.*`` and ``angular.z.*`` limit
  (``wcdrive.ros2.limits``). The controller's other names (the wheel geometry,
  ``open_loop``, ``position_feedback``, ``publish_limited_velocity``,
  ``velocity_rolling_window_size``) are taken, checked as the controller checks them,
  and not used: the chair's odometry is its own (``unused``).
- controller_interface (ros2_control, jazzy): ``update_rate``, ``is_async``,
  ``thread_priority``, which every controller's node declares: taken, not used.
- rclcpp: ``use_sim_time`` (``--sim-time on``/``off``).
- the bridge: ``publish_static_tf`` (false: no ``/tf_static`` at all, for when
  robot_state_publisher owns the static transforms), ``base_frame_offset_x`` (how far
  ``base_frame_id`` is ahead of the drive axle's midpoint, m: odometry is reported for
  that point, and the lidar's transform measured from it), ``lidar_frame_id`` and
  ``imu_frame_id``; and the simulated lidar's mount and driver (``lidar_mount``: x, y,
  z in m and roll, pitch, yaw in rad, as a URDF joint's ``origin`` gives them;
  ``lidar_driver``: ``sllidar_ros2`` or ``rplidar_ros``; ``lidar_inverted`` and
  ``lidar_angle_compensate``, that driver's ``inverted`` and ``angle_compensate``):
  ``lidar_url_options`` turns them into the URL options of the same names
  (``wcdrive.transports.urlhandler.board_serial.LIDAR_DETAILS``: degrees there).

Types are rclcpp's: a parameter declared a double takes a double only (``50`` is an
integer: write ``50.0``), as a node built with generate_parameter_library refuses it.
An unknown name, a wrong type, a value that fails the controller's validation or a value
the bridge cannot honour (``cmd_vel_timeout: 0.0``, which would let the chair drive on
with no command) is a ``ParameterError`` naming the parameter and what to do; an
unknown name lists every known one.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from wcdrive.ros2.limits import AxisLimits
from wcdrive.ros2.params import ParameterError, Value

__all__ = ["PARAMETERS", "Parameter", "StackConfig", "configure", "lidar_url_options"]

DDC = "diff_drive_controller"
CI = "controller_interface"
RCLCPP = "rclcpp"
BRIDGE = "wcdrive"
NAN = math.nan


def _gt(bound: float) -> Callable[[Any], str | None]:
    return lambda v: None if v > bound else f"must be greater than {bound}"


def _gt_eq_or_nan(bound: float) -> Callable[[Any], str | None]:
    return lambda v: None if math.isnan(v) or v >= bound else f"must be >= {bound} or .nan (off)"


def _lt_eq_or_nan(bound: float) -> Callable[[Any], str | None]:
    return lambda v: None if math.isnan(v) or v <= bound else f"must be <= {bound} or .nan (off)"


def _not_empty(v: Any) -> str | None:
    return None if len(v) > 0 else "must not be empty"


def _six(v: Any) -> str | None:
    return None if len(v) == 6 else f"needs 6 values (x, y, z, roll, pitch, yaw), not {len(v)}"


def _frame(v: Any) -> str | None:
    return None if v else "must not be empty"


def _finite(v: Any) -> str | None:
    return None if math.isfinite(v) else "must be finite"


#: How far (rad) a mount's roll or pitch may be from a multiple of pi and be taken as
#: it: a URDF's ``3.14159`` is pi.
PI_SNAP_RAD = 1e-3


def _mount(v: Any) -> str | None:
    if len(v) != 6:
        return f"needs 6 values (x, y, z in m, roll, pitch, yaw in rad), not {len(v)}"
    if not all(math.isfinite(x) for x in v):
        return "must be finite numbers"
    for name, angle in (("roll", v[3]), ("pitch", v[4])):
        turns = angle / math.pi
        if abs(turns - round(turns)) * math.pi > PI_SNAP_RAD:
            return (f"{name} {angle:g} rad: only 0 or pi is modelled (the scan plane level, "
                    "head up or down)")
    return None


def _driver(v: Any) -> str | None:
    from wcdrive.plant.lidar_driver import DRIVERS

    return None if v in DRIVERS else f"must be one of {', '.join(DRIVERS)}"


@dataclass(frozen=True)
class Parameter:
    """One parameter: ``name``, rclcpp ``type``, ``default``, who defines it
    (``owner``), whether the bridge acts on it (``used``), a check (None: any value)."""

    name: str
    type: str
    default: Any
    owner: str
    used: bool
    check: Callable[[Any], str | None] | None = None


def _axis(prefix: str) -> list[Parameter]:
    return [
        Parameter(f"{prefix}.has_velocity_limits", "bool", True, DDC, True),
        Parameter(f"{prefix}.has_acceleration_limits", "bool", True, DDC, True),
        Parameter(f"{prefix}.has_jerk_limits", "bool", True, DDC, True),
        Parameter(f"{prefix}.max_velocity", "double", NAN, DDC, True, _gt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.min_velocity", "double", NAN, DDC, True, _lt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.max_acceleration", "double", NAN, DDC, True, _gt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.max_deceleration", "double", NAN, DDC, True, _lt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.min_acceleration", "double", NAN, DDC, False),
        Parameter(f"{prefix}.max_acceleration_reverse", "double", NAN, DDC, True, _lt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.max_deceleration_reverse", "double", NAN, DDC, True, _gt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.max_jerk", "double", NAN, DDC, True, _gt_eq_or_nan(0.0)),
        Parameter(f"{prefix}.min_jerk", "double", NAN, DDC, True, _lt_eq_or_nan(0.0)),
    ]


#: Every parameter the bridge's node takes (module docstring), by name.
PARAMETERS: dict[str, Parameter] = {p.name: p for p in [
    Parameter("left_wheel_names", "string_array", [], DDC, True, _not_empty),
    Parameter("right_wheel_names", "string_array", [], DDC, True, _not_empty),
    Parameter("wheel_separation", "double", 0.0, DDC, False, _gt(0.0)),
    Parameter("wheel_radius", "double", 0.0, DDC, False, _gt(0.0)),
    Parameter("wheel_separation_multiplier", "double", 1.0, DDC, False),
    Parameter("left_wheel_radius_multiplier", "double", 1.0, DDC, False),
    Parameter("right_wheel_radius_multiplier", "double", 1.0, DDC, False),
    Parameter("tf_frame_prefix_enable", "bool", True, DDC, True),
    Parameter("tf_frame_prefix", "string", "", DDC, True),
    Parameter("odom_frame_id", "string", "odom", DDC, True, _frame),
    Parameter("base_frame_id", "string", "base_link", DDC, True, _frame),
    Parameter("pose_covariance_diagonal", "double_array", [0.0] * 6, DDC, True, _six),
    Parameter("twist_covariance_diagonal", "double_array", [0.0] * 6, DDC, True, _six),
    Parameter("open_loop", "bool", False, DDC, False),
    Parameter("position_feedback", "bool", True, DDC, False),
    Parameter("enable_odom_tf", "bool", True, DDC, True),
    Parameter("cmd_vel_timeout", "double", 0.5, DDC, True),
    Parameter("publish_limited_velocity", "bool", False, DDC, False),
    Parameter("velocity_rolling_window_size", "integer", 10, DDC, False),
    Parameter("publish_rate", "double", 50.0, DDC, True, _gt(0.0)),
    *_axis("linear.x"),
    *_axis("angular.z"),
    Parameter("update_rate", "integer", 0, CI, False),
    Parameter("is_async", "bool", False, CI, False),
    Parameter("thread_priority", "integer", -100, CI, False),
    Parameter("use_sim_time", "bool", False, RCLCPP, True),
    Parameter("publish_static_tf", "bool", True, BRIDGE, True),
    Parameter("base_frame_offset_x", "double", 0.0, BRIDGE, True, _finite),
    Parameter("lidar_frame_id", "string", "laser", BRIDGE, True, _frame),
    Parameter("imu_frame_id", "string", "imu_link", BRIDGE, True, _frame),
    Parameter("lidar_mount", "double_array", [], BRIDGE, True, _mount),
    Parameter("lidar_driver", "string", "sllidar_ros2", BRIDGE, True, _driver),
    Parameter("lidar_inverted", "bool", False, BRIDGE, True),
    Parameter("lidar_angle_compensate", "bool", True, BRIDGE, True),
]}
#: The parameters that configure the simulated lidar (``lidar_url_options``).
LIDAR_PARAMETERS = ("lidar_mount", "lidar_driver", "lidar_inverted", "lidar_angle_compensate")


@dataclass
class StackConfig:
    """What the parameters ask of the bridge. A field is None where no parameter said
    (the bridge's flags and defaults decide); ``given`` holds every parameter that was
    set, ``unused`` those taken but not acted on."""

    odom_frame: str = "odom"
    base_frame: str = "base_link"
    lidar_frame: str | None = None
    imu_frame: str | None = None
    left_joints: tuple[str, ...] | None = None
    right_joints: tuple[str, ...] | None = None
    enable_odom_tf: bool | None = None
    publish_static_tf: bool = True
    base_offset: float = 0.0
    cmd_vel_timeout: float | None = None
    publish_rate: float | None = None
    pose_covariance_diagonal: tuple[float, ...] | None = None
    twist_covariance_diagonal: tuple[float, ...] | None = None
    linear: AxisLimits = field(default_factory=AxisLimits)
    angular: AxisLimits = field(default_factory=AxisLimits)
    use_sim_time: bool | None = None
    lidar: dict[str, Any] = field(default_factory=dict)
    given: dict[str, Any] = field(default_factory=dict)
    unused: list[str] = field(default_factory=list)


def known_names() -> str:
    """Every known name, grouped by owner, for messages."""
    groups: dict[str, list[str]] = {}
    for p in PARAMETERS.values():
        groups.setdefault(p.owner, []).append(p.name)
    return "; ".join(f"{owner}: {', '.join(names)}" for owner, names in groups.items())


def _a(kind: str) -> str:
    """"a double", "an integer", "a string array"."""
    words = kind.replace("_", " ")
    return ("an " if words[0] in "aeiou" else "a ") + words


def _typed(name: str, value: Value, node: str) -> Any:
    param = PARAMETERS[name]
    if value.type == "not set":
        raise ParameterError(f"parameter {name!r} of {node} has no value (an empty list or map): "
                             f"give it {_a(param.type)}")
    if value.type != param.type:
        hint = ""
        if param.type == "double" and value.type == "integer":
            hint = f" (write {value.value}.0)"
        elif param.type == "double_array" and value.type == "integer_array":
            hint = " (write each number with a decimal point, e.g. 0.0)"
        raise ParameterError(f"parameter {name!r} of {node} is {_a(param.type)}, "
                             f"and {value.yaml()} is {_a(value.type)}{hint}")
    if param.check is not None:
        why = param.check(value.value)
        if why:
            raise ParameterError(f"parameter {name!r} of {node} = {value.yaml()}: {why}")
    return value.value


def configure(values: dict[str, Value], namespace: str = "/", node: str = "the node") -> StackConfig:
    """The ``StackConfig`` of the parameter values ``values`` given to node ``node`` in
    ``namespace`` (module docstring); ``ParameterError`` for any it cannot take."""
    unknown = [name for name in values if name not in PARAMETERS]
    if unknown:
        near = {n: difflib.get_close_matches(n, PARAMETERS, n=1) for n in unknown}
        hints = "".join(f" ({n!r}: did you mean {m[0]!r}?)" for n, m in near.items() if m)
        raise ParameterError(f"unknown parameter{'s' if len(unknown) > 1 else ''} "
                             f"{', '.join(map(repr, unknown))} for {node}{hints}; the known ones are "
                             f"{known_names()}")
    given = {name: _typed(name, value, node) for name, value in values.items()}

    def get(name: str) -> Any:
        return given.get(name, PARAMETERS[name].default)

    config = StackConfig(given=given, unused=[n for n in given if not PARAMETERS[n].used])
    prefix = ""
    if get("tf_frame_prefix_enable"):
        prefix = get("tf_frame_prefix") or namespace
        prefix = prefix if prefix.endswith("/") else prefix + "/"
        prefix = prefix[1:] if prefix.startswith("/") else prefix
    config.odom_frame = prefix + get("odom_frame_id")
    config.base_frame = prefix + get("base_frame_id")
    config.lidar_frame = given.get("lidar_frame_id")
    config.imu_frame = given.get("imu_frame_id")
    left, right = given.get("left_wheel_names"), given.get("right_wheel_names")
    if (left is None) != (right is None):
        raise ParameterError(f"{node}: give left_wheel_names and right_wheel_names together "
                             f"(got only {'left' if right is None else 'right'}_wheel_names)")
    if left is not None and right is not None:
        if len(left) != len(right):
            raise ParameterError(f"{node}: the number of left wheels [{len(left)}] and the number of "
                                 f"right wheels [{len(right)}] are different")
        config.left_joints, config.right_joints = tuple(left), tuple(right)
    config.enable_odom_tf = given.get("enable_odom_tf")
    config.publish_static_tf = get("publish_static_tf")
    config.base_offset = get("base_frame_offset_x")
    if "cmd_vel_timeout" in given:
        timeout = given["cmd_vel_timeout"]
        if not timeout > 0.0:
            raise ParameterError(
                f"parameter 'cmd_vel_timeout' of {node} = {timeout}: the bridge needs a timeout above 0 "
                "(diff_drive_controller takes 0.0 as 'never time out', which would keep a person's "
                "chair driving on the last command when its publisher dies)")
        config.cmd_vel_timeout = timeout
    config.publish_rate = given.get("publish_rate")
    for name in ("pose_covariance_diagonal", "twist_covariance_diagonal"):
        if name in given:
            setattr(config, name, tuple(float(v) for v in given[name]))
    for axis in ("linear.x", "angular.z"):
        fields = {key.split(".")[-1]: value for key, value in given.items() if key.startswith(axis + ".")}
        limits = AxisLimits(**fields)
        try:
            limits.limiter()
        except ValueError as exc:
            raise ParameterError(f"{node}: the {axis} limits {limits.describe()} are refused as "
                                 f"diff_drive_controller refuses them: {exc}") from None
        setattr(config, axis.split(".")[0], limits)
    config.use_sim_time = given.get("use_sim_time")
    config.lidar = {name: given[name] for name in LIDAR_PARAMETERS if name in given}
    return config


def lidar_url_options(config: StackConfig) -> dict[str, str]:
    """The URL options (``lidar_mount=x,y,z,roll,pitch,yaw`` in m and degrees,
    ``lidar_driver=``, ``lidar_inverted=``, ``lidar_angle_compensate=``) that give a
    simulated chair the lidar the parameters ``config.lidar`` describe; a roll or pitch
    within ``PI_SNAP_RAD`` of a multiple of pi is that multiple."""
    out: dict[str, str] = {}
    for name, value in config.lidar.items():
        if name == "lidar_mount":
            x, y, z, *angles = (float(v) for v in value)
            roll, pitch = (180.0 * round(a / math.pi) for a in angles[:2])
            out[name] = ",".join(repr(v) for v in (x, y, z, roll, pitch, math.degrees(angles[2])))
        elif isinstance(value, bool):
            out[name] = "true" if value else "false"
        else:
            out[name] = str(value)
    return out
