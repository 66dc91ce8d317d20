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

Names (``Options.names``, a ``wcdrive.ros2.names.NodeNames``: the node's name, namespace
and remap rules from ``--ros-args``): the node creates ``~/odom`` and ``~/cmd_vel`` as
diff_drive_controller does, ``joint_states``, ``imu``, ``scan``, ``estop`` and
``estop_reset`` in its namespace, and ``/tf``, ``/tf_static``, ``/diagnostics``,
``/clock`` absolute (``CREATED``). After the given rules come two of the bridge's own,
``NAME:~/odom:=odom`` and ``NAME:~/cmd_vel:=cmd_vel`` (``NAME``: the name the node was
created with, ``--name``), so that ``wcdrive ros2`` alone keeps ``/odom`` and
``/cmd_vel``; once ``__node`` renames the node they no longer apply and the two topics
follow the node (``/wheelchair_controller/odom``), as the controller's do.

diff_drive_controller's behaviour, from its parameters (``Options.with_parameters``,
``wcdrive.ros2.controller``): each control period (``PERIOD``) the newest command is
limited as the controller limits it (``wcdrive.ros2.limits.CommandLimiter``: velocity,
acceleration, jerk) and what was limited is counted (``wcdrive: limits`` in
``/diagnostics``); with ``cmd_vel_timeout`` a command times out that long after its
stamp (its arrival for a zero stamp or a ``Twist``), and then the reference is zero,
which the limits ramp down to before the chair is stopped; ``/odom`` and ``/tf`` at
most ``publish_rate`` times a second; fixed covariance diagonals; the joints' names;
and the pose and twist of a base frame ``base_offset`` m ahead of the axle.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from wcdrive.errors import WcdriveError
from wcdrive.host.robot import BoardHealthSurface, EstopSurface, LidarSurface, NamedSurface, Robot
from wcdrive.host.telemetry import Telemetry
from wcdrive.ros2.bridge import laser_scan, tf_static
from wcdrive.ros2.dds import messages, qos
from wcdrive.ros2.dds.cmdvel import CmdVelGate
from wcdrive.ros2.dds.graph import RosNode
from wcdrive.ros2.limits import AxisLimits, CommandLimiter
from wcdrive.ros2.names import NodeNames, RemapRule
from wcdrive.ros2.topics import TABLE, Topic

if TYPE_CHECKING:
    from wcdrive.plant.lidar import LaserScan
    from wcdrive.ros2.controller import StackConfig

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
#: The name the node creates each topic under, where it is not the table's absolute
#: one: diff_drive_controller's two node-private topics, and the relative ones that
#: follow the node's namespace (module docstring).
CREATED: dict[str, str] = {"/odom": "~/odom", "/cmd_vel": "~/cmd_vel", "/joint_states": "joint_states",
                           "/imu": "imu", "/scan": "scan", "/estop": "estop", "/estop_reset": "estop_reset"}


def own_rules(created_name: str) -> tuple[RemapRule, ...]:
    """The bridge's rules after the given ones: ``/odom`` and ``/cmd_vel`` in the node's
    namespace while the node keeps the name it was created with (module docstring)."""
    return tuple(RemapRule("name", name, match=f"~/{name}", node=created_name,
                           text=f"{created_name}:~/{name}:={name}") for name in ("odom", "cmd_vel"))
#: How often the last good ``/cmd_vel`` is sent again (s).
RESEND = 0.1
#: The control loop's period (s): how often ``/cmd_vel`` is read and the limits applied.
PERIOD = 0.02
#: A limited command this small (m/s, rad/s) once the reference is zero counts as zero:
#: the ramp down is over and the chair is stopped.
STILL = 1e-6


class ScanSource(Protocol):
    """What ``/scan`` needs: the latest ``sensor_msgs/msg/LaserScan`` as a dict (its
    header's stamp and frame set), or None when there is no new one."""

    def scan(self) -> dict[str, Any] | None:
        """The newest scan not yet returned, or None."""


class RobotScans:
    """A ``ScanSource`` of a robot with a lidar (``LidarSurface.on_scan``): its newest scan,
    stamped at its first beam on the node's clock (``stamp(host_s, board_s)``)."""

    def __init__(self, robot: LidarSurface, stamp: Callable[[float, float], float]) -> None:
        self._stamp = stamp
        self._lock = threading.Lock()
        self._latest: LaserScan | None = None
        robot.on_scan(self._on_scan)

    def _on_scan(self, scan: LaserScan) -> None:
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
    """How the node behaves (``wcdrive ros2``'s flags, and the ROS parameters through
    ``with_parameters``). ``names``: the node's names and remap rules (None: the
    ``RosNode``'s name and namespace, no rules). ``cmd_timeout_from_stamp``: the
    timeout counts from a command's stamp (``cmd_vel_timeout``), not its arrival.
    ``lidar_frame`` None: the lidar's own. ``publish_rate`` None: every tick.
    ``*_covariance_diagonal`` None: the chair's own covariances."""

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
    names: NodeNames | None = None
    publish_static_tf: bool = True
    imu_frame: str = messages.IMU_FRAME
    lidar_frame: str | None = None
    left_joints: tuple[str, ...] = (messages.WHEEL_JOINTS[0],)
    right_joints: tuple[str, ...] = (messages.WHEEL_JOINTS[1],)
    base_offset: float = 0.0
    publish_rate: float | None = None
    pose_covariance_diagonal: tuple[float, ...] | None = None
    twist_covariance_diagonal: tuple[float, ...] | None = None
    linear_limits: AxisLimits = dataclasses.field(default_factory=AxisLimits)
    angular_limits: AxisLimits = dataclasses.field(default_factory=AxisLimits)
    cmd_timeout_from_stamp: bool = False

    def with_parameters(self, config: StackConfig) -> Options:
        """These options with what the ROS parameters ``config`` say
        (``wcdrive.ros2.controller.configure``): ``enable_odom_tf: false`` turns ``/tf``
        off as ``publish_tf=False`` does (either turns it off), ``cmd_vel_timeout``
        replaces ``cmd_timeout`` (and ``max_age``: a command older than the timeout is
        dropped, as the controller drops it), ``use_sim_time`` sets ``sim_time``."""
        out = dataclasses.replace(
            self, odom_frame=config.odom_frame, base_frame=config.base_frame,
            publish_tf=self.publish_tf and config.enable_odom_tf is not False,
            publish_static_tf=config.publish_static_tf, base_offset=config.base_offset,
            publish_rate=config.publish_rate, pose_covariance_diagonal=config.pose_covariance_diagonal,
            twist_covariance_diagonal=config.twist_covariance_diagonal,
            linear_limits=config.linear, angular_limits=config.angular)
        if config.imu_frame is not None:
            out.imu_frame = config.imu_frame
        if config.lidar_frame is not None:
            out.lidar_frame = config.lidar_frame
        if config.left_joints is not None and config.right_joints is not None:
            out.left_joints, out.right_joints = config.left_joints, config.right_joints
        if config.cmd_vel_timeout is not None:
            out.cmd_timeout = out.max_age = config.cmd_vel_timeout
            out.cmd_timeout_from_stamp = True
        if config.use_sim_time is not None:
            out.sim_time = config.use_sim_time
        return out


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
    ``close()`` (which stops the robot but leaves it open).

    Beyond ``Robot``, the node serves the extras a robot has (``wcdrive.host.robot``;
    ``Wheelchair`` has all three): with an ``EstopSurface``, ``/estop`` latches the
    robot's e-stop and the board's latch drops ``/cmd_vel`` too (without, ``/estop``
    stops the robot and latches the node's own); with a ``BoardHealthSurface``,
    ``/diagnostics`` carries its line counts, faults and ``TLM:`` line, and its ``url``
    is the hardware id (else a ``NamedSurface``'s ``name``, the Eddie's); with a
    ``LidarSurface`` that has a lidar, ``/scan`` and the lidar's ``/tf_static``."""

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
        self._estop: EstopSurface | None = robot if isinstance(robot, EstopSurface) else None
        self._health: BoardHealthSurface | None = robot if isinstance(robot, BoardHealthSurface) else None
        self._lidar: LidarSurface | None = robot if isinstance(robot, LidarSurface) else None
        if o.scan is None and self._lidar is not None and self._lidar.has_lidar:
            o.scan = RobotScans(self._lidar, self._scan_stamp)
        self.limiter = CommandLimiter(o.linear_limits, o.angular_limits)
        self._last_odom: float | None = None
        names = o.names or NodeNames.init(ros.name, ros.namespace)
        resolver = dataclasses.replace(names, rules=names.rules + own_rules(names.given or names.name))
        #: The table's topic name -> the fully qualified name the node uses (after remaps).
        self.topic_names = {t.name: resolver.resolve(CREATED.get(t.name, t.name)) for t in TOPICS}
        self._pub: dict[str, Any] = {}
        for topic in TOPICS:
            if topic.direction != "pub" or not self._wanted(topic.name, imu):
                continue
            self._pub[topic.name] = ros.publisher(self.topic_names[topic.name], topic.msgtype, topic.profile)
        self._cmd_type = TWIST if o.twist else TWIST_STAMPED
        self._cmd_reader = ros.subscription(self.topic_names["/cmd_vel"], self._cmd_type, qos.COMMAND)
        self._estop_reader = ros.subscription(self.topic_names["/estop"], BOOL, qos.DEFAULT)
        self._reset_reader = ros.subscription(self.topic_names["/estop_reset"], EMPTY, qos.DEFAULT)
        if imu is not None:
            imu.callback = self._on_imu

    @property
    def published(self) -> list[str]:
        """The ROS topics this node publishes (``TOPICS`` less those not wanted), by the
        names it uses (after remaps)."""
        return [self.topic_names[name] for name in self._pub]

    def _wanted(self, name: str, imu: ImuTap | None) -> bool:
        o = self.options
        return {"/tf": o.publish_tf, "/imu": imu is not None, "/scan": o.scan is not None,
                "/clock": o.sim_time, "/tf_static": o.publish_static_tf}.get(name, True)

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
        if o.publish_static_tf:
            statics = [messages.transform(self.now(), o.base_frame, o.imu_frame)]
            lidar = self._lidar.lidar if self._lidar is not None else None
            if lidar is not None:   # the mount is from the axle; base_frame is base_offset ahead
                m = lidar.mount     # its laser frame: Rz(yaw) Rx(tf_roll), LidarMount.laser_rotation
                statics += tf_static(self.now(), o.lidar_frame or lidar.frame_id, m.x - o.base_offset, m.y,
                                     m.z, m.yaw, m.tf_roll, o.base_frame)["transforms"]
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
        if self._odometry_due(t):
            odom = messages.odometry(t, estimate, o.odom_frame, o.base_frame, o.base_offset,
                                     o.pose_covariance_diagonal, o.twist_covariance_diagonal)
            self._pub["/odom"].publish(odom)
            if o.publish_tf:
                position = odom["pose"]["pose"]["position"]
                self._pub["/tf"].publish({"transforms": [messages.transform(
                    t, o.odom_frame, o.base_frame, position["x"], position["y"], yaw=estimate.pose.theta)]})
        self._pub["/joint_states"].publish(messages.joint_state(
            t, self._wheels(tel), (tel.vel_left, tel.vel_right), o.base_frame, o.left_joints, o.right_joints))
        if o.sim_time:
            self._pub["/clock"].publish({"clock": messages.stamp(t)})

    def _odometry_due(self, t: float) -> bool:
        """Whether ``/odom`` and ``/tf`` go out at stamp ``t``: every tick, or with
        ``publish_rate`` as diff_drive_controller decides (``previous + period < t``, then
        ``previous += period``; the first at once)."""
        rate = self.options.publish_rate
        if rate is None:
            return True
        if self._last_odom is None or t < self._last_odom - 1.0:        # the first, or a clock reset
            self._last_odom = t
            return True
        if self._last_odom + 1.0 / rate < t:
            self._last_odom += 1.0 / rate
            return True
        return False

    def _on_imu(self, message: dict[str, Any]) -> None:
        if self._stop.is_set():
            return
        message["header"]["frame_id"] = self.options.imu_frame
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
        o = self.options
        reference: tuple[float, float] | None = None
        received = sent = stopped = -math.inf
        last_sent: tuple[float, float] | None = None
        last_step = time.monotonic()
        next_diagnostics = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            dt, last_step = now - last_step, now
            fresh = self._read_commands()
            if fresh is not None:
                reference, stamp = fresh
                received = (stamp if stamp is not None else self.now()) if o.cmd_timeout_from_stamp else now
                sent = -math.inf
            self._read_estop()
            latched = self.estop_held or self._board_estop()
            age = (self.now() if o.cmd_timeout_from_stamp else now) - received
            live = reference is not None and not latched and age <= o.cmd_timeout
            if not live:
                reference = None        # timed out (or dropped): the reference is zero, as the controller's
            if latched:
                self.limiter.reset()
                command = None
            else:
                command = self.limiter.step(reference if reference is not None else (0.0, 0.0), dt)
            if command is not None and (live or max(abs(command[0]), abs(command[1])) > STILL):
                if command != last_sent or now - sent >= RESEND:        # a ramp is sent each period
                    sent, last_sent = now, command
                    self._drive(command)
            elif last_sent is not None or now - stopped >= 1.0:
                last_sent, stopped = None, now
                self.limiter.reset()
                self._halt()
            if o.scan is not None:
                scan = o.scan.scan()
                if scan is not None:
                    if o.lidar_frame:
                        scan["header"]["frame_id"] = o.lidar_frame
                    self._pub["/scan"].publish(scan)
            if now >= next_diagnostics:
                next_diagnostics = now + 1.0
                self._publish_diagnostics()
            self._stop.wait(PERIOD)

    def _read_commands(self) -> tuple[tuple[float, float], float | None] | None:
        """The newest ``/cmd_vel`` that passes the gate and its stamp on the node's
        clock (None: a plain ``Twist`` or a zero stamp), or None."""
        from wcdrive.ros2.dds import types

        newest = None
        for sample in self._cmd_reader.take(N=64):
            if not getattr(sample.sample_info, "valid_data", True):
                continue
            message = types.to_dict(self._cmd_type, sample)
            if self.estop_held or self._board_estop():
                self.gate.counts["estop"] += 1
                continue
            stamp = None
            if self._cmd_type == TWIST_STAMPED:
                header = message["header"]["stamp"]
                checked = self.gate.check(message["twist"], self.now(), header)
                if header["sec"] or header["nanosec"]:
                    stamp = messages.seconds(header)
            else:
                checked = self.gate.check(message, self.now())
            if checked is not None:
                newest = (checked, stamp)
        return newest

    def _read_estop(self) -> None:
        for sample in self._estop_reader.take(N=16):
            if getattr(sample.sample_info, "valid_data", True) and sample.data:
                self.estop()
        resets = [s for s in self._reset_reader.take(N=16) if getattr(s.sample_info, "valid_data", True)]
        if resets:
            self.reset_estop()

    def _board_estop(self) -> bool:
        return self._estop is not None and self._estop.estop_latched

    def estop(self) -> None:
        """Latches this node's e-stop, which drops every ``/cmd_vel`` until
        ``reset_estop``, and the robot's (``EstopSurface.estop``; a robot without one is
        stopped)."""
        self.estop_held = True
        try:
            if self._estop is not None:
                self._estop.estop()
            else:
                self.robot.stop()
        except WcdriveError as exc:
            self._note(f"estop: {exc}")
            self._halt()

    def reset_estop(self) -> None:
        """Releases the node's e-stop, and the robot's once it has parked."""
        try:
            if self._estop is not None:
                self._estop.reset_estop()
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

    def _hardware_id(self) -> str:
        """The diagnostics' ``hardware_id``: the board's ``url`` (``BoardHealthSurface``),
        else the robot's ``name`` (``NamedSurface``), else ""."""
        if self._health is not None:
            return self._health.url
        return self.robot.name if isinstance(self.robot, NamedSurface) else ""

    def _publish_diagnostics(self) -> None:
        health, hardware = self._health, self._hardware_id()
        link = self.robot.link_ok
        link_values: dict[str, Any] = {"link_ok": link}
        if health is not None:
            link_values.update(dataclasses.asdict(health.link_stats))
        faults = health.faults if health is not None else ()
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
        if self.limiter.active:
            statuses.append(self._limits_status(hardware))
        tlm = health.status if health is not None else None
        if tlm is not None:
            statuses.append(messages.status("wcdrive: TLM", messages.OK, "the board's last TLM line",
                                            hardware, dataclasses.asdict(tlm)))
            statuses.append(messages.motor_heat(tlm, hardware))
            statuses.append(messages.battery(tlm, hardware))
            statuses.append(messages.drive_profile(tlm, hardware))
        try:
            self._pub["/diagnostics"].publish(messages.diagnostics(self.now(), statuses))
        except Exception as exc:
            self._note(f"diagnostics: {exc}")

    def _limits_status(self, hardware: str) -> dict[str, Any]:
        """``wcdrive: limits``: how many control periods each limit was active in, per axis
        and stage, and the limits in force (``linear.x.max_velocity``, ...)."""
        limiter = self.limiter
        values: dict[str, Any] = {}
        for axis, limits in zip(limiter.AXES, (limiter.linear, limiter.angular), strict=True):
            for stage in ("velocity", "acceleration", "jerk"):
                values[f"{axis} {stage} limited"] = limiter.counts[f"{axis} {stage}"]
            values.update({f"{axis}.{name}": value for name, value in limits.describe().items()})
        counted = ", ".join(f"{key} {n}" for key, n in sorted(limiter.counts.items()) if n)
        return messages.status("wcdrive: limits", messages.OK,
                               f"periods limited: {counted}" if counted else "nothing limited",
                               hardware, values)

    def close(self) -> None:
        """Stops the loop and the robot (it stays open) and leaves the graph."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._halt()
        self.ros.close()
