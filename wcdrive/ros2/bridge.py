"""ROS 2 messages for the chair's data, and where they go: an MCAP file (``McapSink``,
written with the ``mcap`` and ``mcap-ros2-support`` packages) or Foxglove's WebSocket
server (``LiveSink``, ``foxglove-sdk``). No ROS installation is needed: the message
definitions are ROS 2's own (Humble), spelled out here, and the messages are plain
dicts serialised to CDR.

The topics (``TOPICS``): ``/odom`` (``nav_msgs/msg/Odometry``), ``/imu``
(``sensor_msgs/msg/Imu``: the gyro), ``/cmd_vel`` (``geometry_msgs/msg/Twist``),
``/tf`` (``tf2_msgs/msg/TFMessage``: odom -> base_link), ``/joint_states``
(``sensor_msgs/msg/JointState``: the wheels), ``/ground_truth`` (``nav_msgs/msg/Odometry``:
the plant, in simulation), ``/diagnostics/serial`` (``diagnostic_msgs/msg/DiagnosticArray``:
each raw line from the board) and ``/odometry/filtered`` (the EKF, when there is one).

``ChairPublisher`` turns a ``Wheelchair``'s ticks into these messages (``connect(url,
record="run.mcap")``); ``wcdrive.sim.rosout`` does the same for a simulated run.
"""

from __future__ import annotations

import math
import re
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from wcdrive.transports.wrapper import PortWrapper

#: Topic -> message type.
TOPICS: dict[str, str] = {
    "/odom": "nav_msgs/msg/Odometry",
    "/imu": "sensor_msgs/msg/Imu",
    "/cmd_vel": "geometry_msgs/msg/Twist",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/ground_truth": "nav_msgs/msg/Odometry",
    "/diagnostics/serial": "diagnostic_msgs/msg/DiagnosticArray",
    "/odometry/filtered": "nav_msgs/msg/Odometry",
}
ODOM_FRAME, BASE_FRAME = "odom", "base_link"
WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")

#: ROS 2 Humble's definitions (constants and comments left out), by ``pkg/Type``.
_DEFS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation",
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance",
    "geometry_msgs/Twist": "Vector3 linear\nVector3 angular",
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform",
    "nav_msgs/Odometry": ("std_msgs/Header header\nstring child_frame_id\n"
                          "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist"),
    "sensor_msgs/Imu": ("std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
                        "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
                        "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
                        "float64[9] linear_acceleration_covariance"),
    "sensor_msgs/JointState": ("std_msgs/Header header\nstring[] name\nfloat64[] position\n"
                               "float64[] velocity\nfloat64[] effort"),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms",
    "diagnostic_msgs/KeyValue": "string key\nstring value",
    "diagnostic_msgs/DiagnosticStatus": ("byte level\nstring name\nstring message\nstring hardware_id\n"
                                         "KeyValue[] values"),
    "diagnostic_msgs/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status",
}
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}
_SEPARATOR = "=" * 80


def _dependencies(name: str, seen: list[str]) -> None:
    package = name.split("/")[0]
    for line in _DEFS[name].splitlines():
        kind = re.sub(r"\[\d*\]$", "", line.split()[0])
        if kind in _PRIMITIVES:
            continue
        full = kind if "/" in kind else f"{package}/{kind}"
        if full not in seen:
            seen.append(full)
            _dependencies(full, seen)


def msgdef(typename: str) -> str:
    """The full ``ros2msg`` definition of ``typename`` (``pkg/msg/Type``), its
    dependencies appended as ``MSG: pkg/Type`` sections, as MCAP's ros2msg schemas take it."""
    name = typename.replace("/msg/", "/")
    seen: list[str] = []
    _dependencies(name, seen)
    parts = [_DEFS[name]] + [f"{_SEPARATOR}\nMSG: {dep}\n{_DEFS[dep]}" for dep in seen]
    return "\n".join(parts) + "\n"


# ---- messages ---------------------------------------------------------------------------
def stamp(seconds: float) -> dict[str, int]:
    """``builtin_interfaces/Time`` of ``seconds``."""
    ns = round(seconds * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _header(seconds: float, frame: str) -> dict[str, Any]:
    return {"stamp": stamp(seconds), "frame_id": frame}


def _quaternion(yaw: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(0.5 * yaw), "w": math.cos(0.5 * yaw)}


def _v3(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> dict[str, float]:
    return {"x": x, "y": y, "z": z}


def _cov(matrix: np.ndarray | None, size: int) -> list[float]:
    if matrix is None:
        return [0.0] * size
    return [float(v) for v in np.asarray(matrix, dtype=float).reshape(-1)]


def odometry(t: float, x: float, y: float, yaw: float, linear: float, angular: float,
             pose_covariance: np.ndarray | None = None, twist_covariance: np.ndarray | None = None,
             frame: str = ODOM_FRAME, child: str = BASE_FRAME) -> dict[str, Any]:
    """``nav_msgs/msg/Odometry`` (covariances: 6x6, the ekf.yaml layout)."""
    return {"header": _header(t, frame), "child_frame_id": child,
            "pose": {"pose": {"position": _v3(x, y), "orientation": _quaternion(yaw)},
                     "covariance": _cov(pose_covariance, 36)},
            "twist": {"twist": {"linear": _v3(linear), "angular": _v3(z=angular)},
                      "covariance": _cov(twist_covariance, 36)}}


def imu(t: float, rate: float, rate_variance: float, frame: str = BASE_FRAME) -> dict[str, Any]:
    """``sensor_msgs/msg/Imu`` of a z-gyro: no orientation, no acceleration (their
    covariances' first element -1, REP 145)."""
    unknown = [-1.0] + [0.0] * 8
    return {"header": _header(t, frame), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            "orientation_covariance": unknown, "angular_velocity": _v3(z=rate),
            "angular_velocity_covariance": [1e6, 0, 0, 0, 1e6, 0, 0, 0, rate_variance],
            "linear_acceleration": _v3(), "linear_acceleration_covariance": list(unknown)}


def twist(linear: float, angular: float) -> dict[str, Any]:
    """``geometry_msgs/msg/Twist``."""
    return {"linear": _v3(linear), "angular": _v3(z=angular)}


def tf(t: float, x: float, y: float, yaw: float, frame: str = ODOM_FRAME,
       child: str = BASE_FRAME) -> dict[str, Any]:
    """``tf2_msgs/msg/TFMessage`` with one transform, ``frame`` -> ``child``."""
    return {"transforms": [{"header": _header(t, frame), "child_frame_id": child,
                            "transform": {"translation": _v3(x, y), "rotation": _quaternion(yaw)}}]}


def joint_state(t: float, positions: tuple[float, float], velocities: tuple[float, float]) -> dict[str, Any]:
    """``sensor_msgs/msg/JointState`` of the two wheels (rad, rad/s, forward positive)."""
    return {"header": _header(t, BASE_FRAME), "name": list(WHEEL_JOINTS),
            "position": [float(p) for p in positions], "velocity": [float(v) for v in velocities],
            "effort": []}


def serial_line(t: float, line: str, hardware_id: str = "wcdrive") -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticArray`` carrying one raw line from the board;
    level WARN (1) for ``ERR:``/``EVT:`` lines, OK (0) otherwise."""
    level = 1 if line.startswith(("ERR:", "EVT:")) else 0
    return {"header": _header(t, ""), "status": [{"level": level, "name": "wcdrive/serial",
                                                   "message": line, "hardware_id": hardware_id,
                                                   "values": []}]}


# ---- sinks ------------------------------------------------------------------------------
class Sink(Protocol):
    """Where messages go: ``publish(topic, message, log_time)`` (log_time in s)."""

    def publish(self, topic: str, message: dict[str, Any], log_time: float) -> None:
        """Sends one message (a dict in the ROS 2 type's field layout) on ``topic``."""

    def close(self) -> None:
        """Flushes and releases whatever the sink holds (a file, a server)."""


class McapSink:
    """Writes ROS 2 messages into an MCAP file (``mcap-ros2-support``'s writer, CDR,
    zstd chunks). ``log_time`` and ``publish_time`` are the messages' stamps."""

    def __init__(self, path: str | Path) -> None:
        from mcap_ros2.writer import Writer

        self.path = Path(path)
        self._file = self.path.open("wb")
        self._writer = Writer(self._file)
        self._schemas: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._closed = False

    def publish(self, topic: str, message: dict[str, Any], log_time: float) -> None:
        """One message on ``topic`` (a key of ``TOPICS``)."""
        typename = TOPICS[topic]
        ns = max(0, round(log_time * 1e9))
        with self._lock:
            if self._closed:
                return
            schema = self._schemas.get(typename)
            if schema is None:
                schema = self._schemas[typename] = self._writer.register_msgdef(typename, msgdef(typename))
            self._writer.write_message(topic, schema, message, log_time=ns, publish_time=ns)

    def close(self) -> None:
        """Finishes the file (its summary and index). Safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.finish()
            self._file.close()


class LiveSink:
    """Serves the messages on Foxglove's WebSocket protocol (``foxglove-sdk``): open
    ``ws://host:port`` in Foxglove. Each topic is a channel with its ``ros2msg`` schema
    and CDR messages."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "wcdrive") -> None:
        import foxglove

        self._foxglove = foxglove
        self._context = foxglove.Context()
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self._context)
        self._channels: dict[str, Any] = {}
        self._encoders: dict[str, Callable[[dict[str, Any]], bytes]] = {}
        self._lock = threading.Lock()
        self._closed = False
        # Every channel before any client: one made while a client is connected is
        # advertised before the server knows it, and a quick subscribe to it is refused
        # ("Unknown channel ID", foxglove-sdk 0.30).
        for topic in TOPICS:
            self._channel(topic)

    @property
    def port(self) -> int:
        """The port the server listens on (``port=0`` picks a free one)."""
        return int(self.server.port)

    def _channel(self, topic: str) -> tuple[Any, Callable[[dict[str, Any]], bytes]]:
        from mcap_ros2._dynamic import serialize_dynamic

        typename = TOPICS[topic]
        channel = self._channels.get(topic)
        if channel is None:
            text = msgdef(typename)
            schema = self._foxglove.Schema(name=typename, encoding="ros2msg", data=text.encode())
            channel = self._foxglove.Channel(topic, schema=schema, message_encoding="cdr",
                                             context=self._context)
            self._channels[topic] = channel
            self._encoders[topic] = serialize_dynamic(typename, text)[typename]
        return channel, self._encoders[topic]

    def publish(self, topic: str, message: dict[str, Any], log_time: float) -> None:
        """One message on ``topic``, to every client subscribed to it."""
        with self._lock:
            channel, encode = self._channel(topic)
        channel.log(encode(message), log_time=max(0, round(log_time * 1e9)))

    def close(self) -> None:
        """Stops the server. Safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self.server.stop()


# ---- a connected chair ------------------------------------------------------------------
_CMDVEL = re.compile(rb"x:(-?[\d.]+),t:(-?[\d.]+),")
_WHEEL = re.compile(rb"r([pn])([\d.]+),l([pn])([\d.]+),")


class ChairPublisher:
    """A connected chair's data as ROS 2 messages on ``sink`` (``connect(url,
    record="run.mcap")``). Per tick: ``/odom`` (``chair.odometry``, its covariances),
    ``/tf`` and ``/joint_states``, stamped with the tick's board time mapped to the
    host (``Telemetry.stamp``); ``/cmd_vel`` for every velocity or wheel command the host
    writes and ``/diagnostics/serial`` for every line the board sends, stamped when the
    host wrote or read them. A simulated board (``sim://``, ``simavr://``) adds
    ``/ground_truth`` and ``/imu`` (its gyro) on its own clock, mapped the same way.
    Stamps are on the wall clock (``time.time``'s epoch)."""

    def __init__(self, sink: Sink, wheel_radius: float, wheelbase: float, counts_per_rev: int) -> None:
        import time as _time

        self.sink = sink
        self._wall = _time.time() - _time.monotonic()
        self._monotonic = _time.monotonic
        self._radius, self._base = wheel_radius, wheelbase
        self._per_count = 2.0 * math.pi / counts_per_rev
        self._partial = bytearray()
        self._lock = threading.Lock()
        self._chair: Any = None
        self._board: Any = None
        self._gyro_seen = 0

    def attach(self, chair: Any, board: Any = None) -> None:
        """Subscribes to ``chair``'s ticks; ``board``: the simulated board, if any."""
        self._chair, self._board = chair, board
        chair.on_telemetry(self._tick)

    def wrote(self, data: bytes) -> None:
        """Bytes the host wrote: a velocity or wheel command is a ``/cmd_vel``."""
        t = self._monotonic() + self._wall
        if m := _CMDVEL.search(data):
            self.sink.publish("/cmd_vel", twist(float(m[1]), float(m[2])), t)
        elif m := _WHEEL.search(data):
            r = float(m[2]) * (-1 if m[1] == b"n" else 1)
            left = float(m[4]) * (-1 if m[3] == b"n" else 1)
            self.sink.publish("/cmd_vel", twist(0.5 * self._radius * (r + left),
                                                self._radius * (r - left) / self._base), t)

    def read(self, data: bytes) -> None:
        """Bytes the host read: each whole line is a ``/diagnostics/serial``."""
        t = self._monotonic() + self._wall
        with self._lock:
            self._partial += data
            lines = []
            while (end := self._partial.find(b"\n")) >= 0:
                lines.append(bytes(self._partial[:end]).rstrip(b"\r").decode("latin-1"))
                del self._partial[:end + 1]
        for line in lines:
            self.sink.publish("/diagnostics/serial", serial_line(t, line), t)

    def _tick(self, tel: Any) -> None:
        chair = self._chair
        if chair is None or tel.stamp is None:
            return
        t = tel.stamp + self._wall
        est = chair.odometry
        p = est.pose
        self.sink.publish("/odom", odometry(t, p.x, p.y, p.theta, est.linear, est.angular,
                                            est.pose_covariance, est.twist_covariance), t)
        self.sink.publish("/tf", tf(t, p.x, p.y, p.theta), t)
        self.sink.publish("/joint_states", joint_state(
            t, (-tel.count_left * self._per_count, tel.count_right * self._per_count),
            (tel.vel_left, tel.vel_right)), t)
        if self._board is not None:
            self._simulated(chair)

    def _simulated(self, chair: Any) -> None:
        board = self._board
        pins = getattr(board, "_pins", None)
        gyro = getattr(getattr(board, "loop", None), "gyro", None) or getattr(pins, "gyro", None)
        with board._lock:
            plant = board.plant
            if plant is None:
                return
            x, y, th = plant.pose
            v, _ = plant.axle_velocity()
            w, now = plant.yaw_rate, plant.time
            samples: list[tuple[float, float]] = []
            if gyro is not None:
                samples = list(zip(gyro.times[self._gyro_seen:], gyro.rates[self._gyro_seen:], strict=True))
                self._gyro_seen = len(gyro.times)
        clock = chair.board_clock
        t = clock.to_host(now) + self._wall
        self.sink.publish("/ground_truth", odometry(t, x, y, th, v, w), t)
        variance = math.radians(getattr(getattr(plant, "p", None), "gyro_noise_dps", 0.0)) ** 2
        for ts, rate in samples:
            stamp_s = clock.to_host(ts) + self._wall
            self.sink.publish("/imu", imu(stamp_s, rate, variance), stamp_s)


class TapPort(PortWrapper):
    """Wraps a ``Port``: what goes through also goes to a ``ChairPublisher`` (a write
    once the wrapped port took it, a read when it brought bytes). It is a ``Port``
    itself (``PortWrapper``)."""

    def __init__(self, port: Any, publisher: ChairPublisher) -> None:
        super().__init__(port)
        self.publisher = publisher

    @property
    def recording(self) -> Any:
        """The wrapped port's recording (a ``RecordingPort``'s), if it has one."""
        return getattr(self.port, "recording", None)

    def on_sent(self, data: bytes) -> None:
        """Publishes what the host wrote."""
        self.publisher.wrote(data)

    def on_read(self, data: bytes) -> bytes:
        """Publishes what the host read (when there is any) and passes it on."""
        if data:
            self.publisher.read(data)
        return data
