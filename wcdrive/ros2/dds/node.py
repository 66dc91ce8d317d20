"""``ChairNode``: a ``Robot`` (the chair or the Eddie) as a ROS 2 node on DDS.

Publishes (``TOPICS``; QoS from ``qos``): ``/odom`` (``robot.odometry`` at every
telemetry tick, with its covariances), ``/tf`` odom -> base_link (same tick; off with
``publish_tf=False`` when an EKF owns that transform), ``/tf_static`` (base_link ->
imu_link, and base_link -> laser for a robot with a lidar; once, transient local),
``/joint_states`` (the wheels), ``/diagnostics``
(link, e-stop, faults, the board's ``TLM:`` line, the ``/cmd_vel`` tallies; 1 Hz),
``/imu`` when an ``imu`` source is given (the simulated board's gyro: ``ImuTap``),
``/scan`` when a ``ScanSource`` is given or the robot has a lidar (``sim://`` and
``simavr://`` with ``lidar=``: ``RobotScans``, each turn of the head), and ``/clock``
with ``sim_time`` (the board's clock, for a backend run faster than real time; every
stamp is then on that clock).

Subscribes ``/cmd_vel`` (``geometry_msgs/msg/TwistStamped``, or ``Twist`` with
``twist=True``), ``/estop`` (``std_msgs/msg/Bool``: true latches the e-stop) and
``/estop_reset`` (``std_msgs/msg/Empty``). A sample drives only when ``CmdVelGate``
lets it; the last one is resent every ``RESEND`` s (the board wants one at >= 2 Hz)
until ``cmd_timeout`` s pass without a new one, and then the chair is stopped. While
the e-stop is latched (by ``/estop``, or on the board) every ``/cmd_vel`` is dropped
(``estop``). If this process dies, nothing resends: the board's watchdog stops the
chair 500 ms after the last command.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from wcdrive.errors import WcdriveError
from wcdrive.host.robot import Robot
from wcdrive.host.telemetry import Telemetry
from wcdrive.ros2.bridge import laser_scan, tf_static
from wcdrive.ros2.dds import messages, qos
from wcdrive.ros2.dds.cmdvel import CmdVelGate
from wcdrive.ros2.dds.graph import RosNode
from wcdrive.ros2.topics import TABLE, Topic

ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
JOINTS = "sensor_msgs/msg/JointState"
IMU = "sensor_msgs/msg/Imu"
SCAN = "sensor_msgs/msg/LaserScan"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
CLOCK = "rosgraph_msgs/msg/Clock"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
TWIST = "geometry_msgs/msg/Twist"
BOOL = "std_msgs/msg/Bool"
EMPTY = "std_msgs/msg/Empty"


#: Every topic the node may have (docs/ros2.md's table): the topic table's rows with a
#: DDS direction (``wcdrive.ros2.topics``).
TOPICS: tuple[Topic, ...] = tuple(t for t in TABLE if t.direction is not None)
#: How often the last good ``/cmd_vel`` is sent again (s).
RESEND = 0.1
#: The control loop's period (s): how often ``/cmd_vel`` is read.
PERIOD = 0.02


class ScanSource(Protocol):
    """What ``/scan`` needs: the latest ``sensor_msgs/msg/LaserScan`` as a dict (its
    header's stamp and frame set), or None when there is no new one."""

    def scan(self) -> dict[str, Any] | None:
        """The newest scan not yet returned, or None."""


class RobotScans:
    """A ``ScanSource`` of a robot with a lidar (``Wheelchair.on_scan``): its newest scan,
    stamped at its first beam on the node's clock (``stamp(host_s, board_s)``)."""

    def __init__(self, robot: Any, stamp: Callable[[float, float], float]) -> None:
        self._stamp = stamp
        self._lock = threading.Lock()
        self._latest: Any = None
        robot.on_scan(self._on_scan)

    def _on_scan(self, scan: Any) -> None:
        with self._lock:
            self._latest = scan

    def scan(self) -> dict[str, Any] | None:
        """``ScanSource.scan``."""
        with self._lock:
            scan, self._latest = self._latest, None
        if scan is None:
            return None
        return laser_scan(dataclasses.replace(scan, stamp=self._stamp(scan.stamp, scan.board_stamp)))


@dataclass
class Options:
    """How the node behaves (``wcdrive ros2``'s flags)."""

    twist: bool = False
    publish_tf: bool = True
    cmd_timeout: float = 0.5
    max_age: float = 0.5
    max_linear: float = 0.0          # 0: the robot's own limits
    max_angular: float = 0.0
    sim_time: bool = False
    odom_frame: str = messages.ODOM_FRAME
    base_frame: str = messages.BASE_FRAME
    scan: ScanSource | None = None


def _as_dict(message: Any) -> Any:
    """A message as a dict: dicts stay, dataclass messages (rosbags') are converted."""
    if isinstance(message, dict):
        return {k: _as_dict(v) for k, v in message.items()}
    if dataclasses.is_dataclass(message) and not isinstance(message, type):
        return {f.name: _as_dict(getattr(message, f.name)) for f in dataclasses.fields(message)
                if not f.name.startswith("_")}
    if isinstance(message, list | tuple):
        return [_as_dict(v) for v in message]
    if hasattr(message, "tolist"):
        return message.tolist()
    return message


class ImuTap:
    """A ``wcdrive.ros2.bridge`` sink that keeps only ``/imu``: pass it as
    ``connect(url, ros=tap)`` and the simulated board's gyro samples reach
    ``callback`` as ``sensor_msgs/msg/Imu`` dicts (stamped on the wall clock)."""

    def __init__(self) -> None:
        self.callback: Callable[[dict[str, Any]], None] | None = None

    def publish(self, topic: str, message: Any, log_time: float) -> None:
        """Hands an ``/imu`` message to ``callback``; every other topic is dropped."""
        if topic == "/imu" and self.callback is not None:
            self.callback(_as_dict(message))

    def close(self) -> None:
        """Hands nothing more on."""
        self.callback = None


class ChairNode:
    """``robot`` on the ROS 2 graph of ``ros`` (module docstring); ``start()``, then
    ``close()`` (which stops the robot but leaves it open)."""

    def __init__(self, robot: Robot, ros: RosNode, options: Options | None = None,
                 imu: ImuTap | None = None) -> None:
        self.robot, self.ros = robot, ros
        self.options = o = options or Options()
        max_linear, max_angular = robot.command_limits
        self.gate = CmdVelGate(o.max_linear or max_linear, o.max_angular or max_angular, o.max_age)
        self._wheels = robot.wheel_angles
        self._wall = time.time() - time.monotonic()
        self._last_board_time = 0.0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.estop_held = False
        self.errors: list[str] = []
        if o.scan is None and getattr(robot, "has_lidar", False):
            o.scan = RobotScans(robot, self._scan_stamp)
        self._pub: dict[str, Any] = {}
        for topic in TOPICS:
            if topic.direction != "pub" or not self._wanted(topic.name, imu):
                continue
            self._pub[topic.name] = ros.publisher(topic.name, topic.msgtype, topic.profile)
        self._cmd_type = TWIST if o.twist else TWIST_STAMPED
        self._cmd_reader = ros.subscription("/cmd_vel", self._cmd_type, qos.DEFAULT)
        self._estop_reader = ros.subscription("/estop", BOOL, qos.DEFAULT)
        self._reset_reader = ros.subscription("/estop_reset", EMPTY, qos.DEFAULT)
        if imu is not None:
            imu.callback = self._on_imu

    @property
    def published(self) -> list[str]:
        """The ROS topics this node publishes (``TOPICS`` less those not wanted)."""
        return list(self._pub)

    def _wanted(self, name: str, imu: ImuTap | None) -> bool:
        o = self.options
        return {"/tf": o.publish_tf, "/imu": imu is not None, "/scan": o.scan is not None,
                "/clock": o.sim_time}.get(name, True)

    # ---- time ------------------------------------------------------------------------
    def now(self) -> float:
        """The node's clock (s): the board's with ``sim_time``, else the wall clock."""
        if self.options.sim_time:
            return self._last_board_time
        return time.monotonic() + self._wall

    def _scan_stamp(self, host_s: float, board_s: float) -> float:
        """A scan's stamp: its board time with ``sim_time``, else its host time on the
        wall clock's epoch (as ``stamp``'s)."""
        return board_s if self.options.sim_time else host_s + self._wall

    def stamp(self, tel: Telemetry) -> float:
        """The stamp (s) of the messages of tick ``tel``: its board time with
        ``sim_time``, else the host time it maps to, on the wall clock's epoch."""
        if self.options.sim_time and tel.board_time is not None:
            self._last_board_time = tel.board_time
            return tel.board_time
        return (tel.stamp if tel.stamp is not None else tel.time) + self._wall

    # ---- publishing ------------------------------------------------------------------
    def start(self) -> ChairNode:
        """Publishes ``/tf_static``, then follows the robot's ticks and ``/cmd_vel``."""
        o = self.options
        statics = [messages.transform(self.now(), o.base_frame, messages.IMU_FRAME)]
        lidar = getattr(self.robot, "lidar", None)
        if lidar is not None:
            m = lidar.mount
            statics += tf_static(self.now(), lidar.frame_id, m.x, m.y, m.z, math.radians(m.yaw_deg),
                                 m.tf_roll, o.base_frame)["transforms"]
        self._pub["/tf_static"].publish({"transforms": statics})
        self.robot.on_telemetry(self._on_tick)
        self._thread = threading.Thread(target=self._run, name="wcdrive-ros2", daemon=True)
        self._thread.start()
        return self

    def _on_tick(self, tel: Telemetry) -> None:
        if self._stop.is_set():
            return
        try:
            self._publish_tick(tel)
        except Exception as exc:        # never let a publish kill the robot's reader thread
            self._note(f"publish: {exc}")

    def _publish_tick(self, tel: Telemetry) -> None:
        o = self.options
        t = self.stamp(tel)
        estimate = self.robot.odometry
        self._pub["/odom"].publish(messages.odometry(t, estimate, o.odom_frame, o.base_frame))
        if o.publish_tf:
            pose = estimate.pose
            self._pub["/tf"].publish({"transforms": [messages.transform(
                t, o.odom_frame, o.base_frame, pose.x, pose.y, yaw=pose.theta)]})
        self._pub["/joint_states"].publish(messages.joint_state(
            t, self._wheels(tel), (tel.vel_left, tel.vel_right), o.base_frame))
        if o.sim_time:
            self._pub["/clock"].publish({"clock": messages.stamp(t)})

    def _on_imu(self, message: dict[str, Any]) -> None:
        if self._stop.is_set():
            return
        message["header"]["frame_id"] = messages.IMU_FRAME
        if self.options.sim_time:
            message["header"]["stamp"] = messages.stamp(self._last_board_time)
        try:
            self._pub["/imu"].publish(message)
        except Exception as exc:
            self._note(f"imu: {exc}")

    def _note(self, text: str) -> None:
        if len(self.errors) < 100:
            self.errors.append(text)

    # ---- the control loop --------------------------------------------------------------
    def _run(self) -> None:
        command: tuple[float, float] | None = None
        received = sent = stopped = -math.inf
        next_diagnostics = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            fresh = self._read_commands()
            if fresh is not None:
                command, received, sent = fresh, now, -math.inf
            self._read_estop()
            if self.estop_held or self._board_estop():
                command = None
            if command is not None and now - received <= self.options.cmd_timeout:
                if now - sent >= RESEND:
                    sent = now
                    self._drive(command)
            elif command is not None or now - stopped >= 1.0:
                command, stopped = None, now
                self._halt()
            if self.options.scan is not None:
                scan = self.options.scan.scan()
                if scan is not None:
                    self._pub["/scan"].publish(scan)
            if now >= next_diagnostics:
                next_diagnostics = now + 1.0
                self._publish_diagnostics()
            self._stop.wait(PERIOD)

    def _read_commands(self) -> tuple[float, float] | None:
        """The newest ``/cmd_vel`` that passes the gate, or None."""
        from wcdrive.ros2.dds import types

        newest = None
        for sample in self._cmd_reader.take(N=64):
            if not getattr(sample.sample_info, "valid_data", True):
                continue
            message = types.to_dict(self._cmd_type, sample)
            if self.estop_held or self._board_estop():
                self.gate.counts["estop"] += 1
                continue
            if self._cmd_type == TWIST_STAMPED:
                checked = self.gate.check(message["twist"], self.now(), message["header"]["stamp"])
            else:
                checked = self.gate.check(message, self.now())
            if checked is not None:
                newest = checked
        return newest

    def _read_estop(self) -> None:
        for sample in self._estop_reader.take(N=16):
            if getattr(sample.sample_info, "valid_data", True) and sample.data:
                self.estop()
        resets = [s for s in self._reset_reader.take(N=16) if getattr(s.sample_info, "valid_data", True)]
        if resets:
            self.reset_estop()

    def _board_estop(self) -> bool:
        return bool(getattr(self.robot, "estop_latched", False))

    def estop(self) -> None:
        """Latches the e-stop: the board's (the chair's ``estop()``) and this node's,
        which drops every ``/cmd_vel`` until ``reset_estop``."""
        self.estop_held = True
        try:
            estop = getattr(self.robot, "estop", None)
            if callable(estop):
                estop()
            else:
                self.robot.stop()
        except WcdriveError as exc:
            self._note(f"estop: {exc}")
            self._halt()

    def reset_estop(self) -> None:
        """Releases the node's e-stop, and the board's once the chair has parked."""
        try:
            reset = getattr(self.robot, "reset_estop", None)
            if callable(reset):
                reset()
        except WcdriveError as exc:
            self._note(f"estop_reset: {exc}")
            return
        self.estop_held = False

    def _drive(self, command: tuple[float, float]) -> None:
        try:
            self.robot.set_velocity(*command)
        except (WcdriveError, ValueError) as exc:
            self.gate.counts["refused"] += 1
            self._note(f"cmd_vel: {exc}")

    def _halt(self) -> None:
        try:
            self.robot.stop()
        except WcdriveError as exc:
            self._note(f"stop: {exc}")

    def _publish_diagnostics(self) -> None:
        robot, hardware = self.robot, str(getattr(self.robot, "url", getattr(self.robot, "name", "")))
        link = robot.link_ok
        link_values: dict[str, Any] = {"link_ok": link}
        stats = getattr(robot, "link_stats", None)
        if stats is not None:
            link_values.update(dataclasses.asdict(stats))
        faults = tuple(getattr(robot, "faults", ()))
        latched = self.estop_held or self._board_estop()
        statuses = [
            messages.status("wcdrive: link", messages.OK if link else messages.ERROR,
                            "ok" if link else "lost", hardware, link_values),
            messages.status("wcdrive: e-stop", messages.ERROR if latched else messages.OK,
                            "latched" if latched else "released", hardware,
                            {"host": self.estop_held, "board": self._board_estop()}),
            messages.status("wcdrive: faults", messages.ERROR if faults else messages.OK,
                            ", ".join(faults) or "none", hardware, {"faults": ",".join(faults)}),
            messages.status("wcdrive: cmd_vel", messages.WARN if self.gate.dropped else messages.OK,
                            f"{self.gate.counts['accepted']} driven, {self.gate.dropped} dropped",
                            hardware, dict(sorted(self.gate.counts.items()))),
        ]
        tlm = getattr(robot, "status", None)
        if dataclasses.is_dataclass(tlm) and not isinstance(tlm, type):
            statuses.append(messages.status("wcdrive: TLM", messages.OK, "the board's last TLM line",
                                            hardware, dataclasses.asdict(tlm)))
        try:
            self._pub["/diagnostics"].publish(messages.diagnostics(self.now(), statuses))
        except Exception as exc:
            self._note(f"diagnostics: {exc}")

    def close(self) -> None:
        """Stops the loop and the robot (it stays open) and leaves the graph."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._halt()
        self.ros.close()
