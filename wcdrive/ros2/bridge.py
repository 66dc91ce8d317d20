"""ROS 2 messages for the chair's data, and where they go: an MCAP file (``McapSink``,
written as ROS 2 Jazzy's rosbag2 writes one) or Foxglove's WebSocket server
(``LiveSink``, ``foxglove-sdk``). No ROS installation is needed: the message
definitions and type hashes come from rosbags' type store for ROS 2 Jazzy
(``msgdef``, ``type_hash``), and the messages are plain dicts serialised to CDR.

The topics (``TOPICS``): ``/odom`` (``nav_msgs/msg/Odometry``), ``/imu``
(``sensor_msgs/msg/Imu``: the gyro), ``/cmd_vel`` (``geometry_msgs/msg/TwistStamped``,
what Jazzy's diff_drive_controller takes), ``/tf`` (``tf2_msgs/msg/TFMessage``: odom ->
base_link), ``/tf_static`` (base_link -> laser, the lidar's mount), ``/scan``
(``sensor_msgs/msg/LaserScan``), ``/map`` (``nav_msgs/msg/OccupancyGrid``: the world),
``/joint_states`` (``sensor_msgs/msg/JointState``: the wheels), ``/ground_truth``
(``nav_msgs/msg/Odometry``: the plant, in simulation), ``/diagnostics/serial``
(``diagnostic_msgs/msg/DiagnosticArray``: each raw line from the board) and
``/odometry/filtered`` (the EKF, when there is one). ``QOS`` is the QoS each is
offered with, the topic table's (``wcdrive.ros2.topics``, which the DDS node reads
too): ``/tf_static`` and ``/map`` are latched (reliable, transient local, keep last 1,
as tf2's static broadcaster and map_server offer them), ``/imu`` and ``/scan`` are
sensor data (best effort, keep last 5), so ``ros2 bag play`` offers each as the live
node does.

``ChairPublisher`` turns a ``Wheelchair``'s ticks into these messages (``connect(url,
record="run.mcap")``); ``wcdrive.sim.rosout`` does the same for a simulated run.
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from wcdrive.protocol.motion import VelocityCommand, WheelCommand, find_motion
from wcdrive.ros2.topics import TABLE, Profile, by_name
from wcdrive.transports.recording import Recording, recording_of
from wcdrive.transports.wrapper import PortWrapper

if TYPE_CHECKING:
    from wcdrive.boards.simulation import Simulated

#: Topic -> message type: the recorded rows of the topic table (``wcdrive.ros2.topics``).
TOPICS: dict[str, str] = {t.name: t.msgtype for t in TABLE if t.recorded}
ODOM_FRAME, BASE_FRAME, MAP_FRAME = "odom", "base_link", "map"
#: The gyro's frame (base_link -> imu_link is the identity: the gyro reads the chassis's yaw).
IMU_FRAME = by_name("/imu").frame or BASE_FRAME
WHEEL_JOINTS = ("left_wheel_joint", "right_wheel_joint")
#: The ROS distribution whose definitions, hashes and bag format are written.
ROS_DISTRO = "jazzy"


#: Topic -> the QoS its publisher offers, from the topic table (the live DDS node offers
#: the same: ``ros2 bag play`` replays a recording as the node publishes it).
QOS: dict[str, Profile] = {t.name: t.profile for t in TABLE if t.recorded}


def qos(topic: str) -> Profile:
    """The QoS ``topic`` is offered with."""
    return QOS[topic]


@functools.cache
def typestore() -> Any:
    """rosbags' type store for ROS 2 Jazzy."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


@functools.cache
def msgdef(typename: str) -> str:
    """The full ``ros2msg`` definition of ``typename`` (``pkg/msg/Type``), its
    dependencies appended as ``MSG: pkg/Type`` sections, from rosbags' type store
    (``generate_msgdef``): what MCAP's ros2msg schemas hold."""
    text, _ = typestore().generate_msgdef(typename, ros_version=2)
    return str(text)


@functools.cache
def type_hash(typename: str) -> str:
    """The RIHS01 type hash of ``typename`` in ROS 2 Jazzy (rosbag2's
    ``topic_type_hash``)."""
    return str(typestore().hash_rihs01(typename))


@functools.cache
def encoder(typename: str) -> Callable[[dict[str, Any]], bytes]:
    """The CDR serialiser of ``typename``: a dict in the message's field layout (nested
    dicts, lists or numpy arrays; a missing field is zero or empty) to its bytes,
    through rosbags' type store (``serialize_cdr``; arrays of numbers in bulk)."""
    store = typestore()

    def encode(message: dict[str, Any]) -> bytes:
        return bytes(store.serialize_cdr(_build(typename, message), typename))
    return encode


#: ROS 2 primitive -> the numpy type of an array of it.
_NUMPY: dict[str, Any] = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8,
                          "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32,
                          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
                          "float32": np.float32, "float64": np.float64}


def _build(typename: str, value: dict[str, Any] | None) -> Any:
    """The type store's message object of ``typename`` from a dict."""
    from rosbags.typesys.base import Nodetype

    store = typestore()
    value = value or {}
    fields = {}
    for name, (kind, rest) in store.fielddefs[typename][1]:
        fields[name] = _field(kind, rest, value.get(name), Nodetype)
    return store.types[typename](**fields)


def _field(kind: Any, rest: Any, value: Any, nodetype: Any) -> Any:
    if kind == nodetype.BASE:
        base = rest[0]
        if base in ("string", "wstring"):
            return "" if value is None else str(value)
        if base == "bool":
            return bool(value)
        if base in ("float32", "float64"):
            return 0.0 if value is None else float(value)
        return 0 if value is None else int(value)
    if kind == nodetype.NAME:
        return _build(rest, value)
    (inner, inner_rest), count = rest
    if inner == nodetype.BASE and inner_rest[0] in _NUMPY:
        if value is None:
            value = np.zeros(count if kind == nodetype.ARRAY else 0)
        return np.asarray(value, dtype=_NUMPY[inner_rest[0]])
    return [_field(inner, inner_rest, v, nodetype) for v in (value or [])]


# ---- messages ---------------------------------------------------------------------------
def stamp(seconds: float) -> dict[str, int]:
    """``builtin_interfaces/Time`` of ``seconds``."""
    ns = round(seconds * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def header(seconds: float, frame: str) -> dict[str, Any]:
    """A ``std_msgs/msg/Header`` stamped ``seconds`` in ``frame``."""
    return {"stamp": stamp(seconds), "frame_id": frame}


def quaternion(yaw: float) -> dict[str, float]:
    """A ``geometry_msgs/msg/Quaternion`` turned ``yaw`` rad about z."""
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
    return {"header": header(t, frame), "child_frame_id": child,
            "pose": {"pose": {"position": _v3(x, y), "orientation": quaternion(yaw)},
                     "covariance": _cov(pose_covariance, 36)},
            "twist": {"twist": {"linear": _v3(linear), "angular": _v3(z=angular)},
                      "covariance": _cov(twist_covariance, 36)}}


def imu(t: float, rate: float, rate_variance: float, frame: str = IMU_FRAME) -> dict[str, Any]:
    """``sensor_msgs/msg/Imu`` of a z-gyro: no orientation, no acceleration (their
    covariances' first element -1, REP 145)."""
    unknown = [-1.0] + [0.0] * 8
    return {"header": header(t, frame), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            "orientation_covariance": unknown, "angular_velocity": _v3(z=rate),
            "angular_velocity_covariance": [1e6, 0, 0, 0, 1e6, 0, 0, 0, rate_variance],
            "linear_acceleration": _v3(), "linear_acceleration_covariance": list(unknown)}


def twist(linear: float, angular: float) -> dict[str, Any]:
    """``geometry_msgs/msg/Twist``."""
    return {"linear": _v3(linear), "angular": _v3(z=angular)}


def twist_stamped(t: float, linear: float, angular: float, frame: str = BASE_FRAME) -> dict[str, Any]:
    """``geometry_msgs/msg/TwistStamped`` (``/cmd_vel`` in Jazzy)."""
    return {"header": header(t, frame), "twist": twist(linear, angular)}


def _rotation(yaw: float, roll: float = 0.0) -> dict[str, float]:
    """The quaternion of a yaw about z after a roll about x (``Rz(yaw) Rx(roll)``)."""
    cz, sz, cx, sx = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
    return {"x": cz * sx, "y": sz * sx, "z": sz * cx, "w": cz * cx}


def tf_static(t: float, child: str, x: float, y: float, z: float, yaw: float, roll: float = 0.0,
              frame: str = BASE_FRAME) -> dict[str, Any]:
    """``tf2_msgs/msg/TFMessage`` for ``/tf_static``: ``frame`` -> ``child`` at (x, y, z),
    turned by ``yaw`` about z after ``roll`` about x (rad)."""
    return {"transforms": [{"header": header(t, frame), "child_frame_id": child,
                            "transform": {"translation": _v3(x, y, z), "rotation": _rotation(yaw, roll)}}]}


def laser_scan(scan: Any) -> dict[str, Any]:
    """``sensor_msgs/msg/LaserScan`` of a ``wcdrive.plant.lidar.LaserScan`` (stamped at
    its first beam, as the driver stamps it)."""
    return {"header": header(scan.stamp, scan.frame_id), "angle_min": scan.angle_min,
            "angle_max": scan.angle_max, "angle_increment": scan.angle_increment,
            "time_increment": scan.time_increment, "scan_time": scan.scan_time,
            "range_min": scan.range_min, "range_max": scan.range_max,
            "ranges": np.asarray(scan.ranges, dtype=np.float32),
            "intensities": np.asarray(scan.intensities, dtype=np.float32)}


def occupancy_grid(t: float, grid: Any, frame: str = MAP_FRAME) -> dict[str, Any]:
    """``nav_msgs/msg/OccupancyGrid`` of a ``wcdrive.plant.rosmap.OccupancyGrid`` (as
    map_server publishes it: ``map_load_time`` the stamp, the origin's yaw as a
    quaternion)."""
    height, width = grid.data.shape
    x0, y0, yaw = grid.origin
    return {"header": header(t, frame),
            "info": {"map_load_time": stamp(t), "resolution": float(grid.resolution), "width": width,
                     "height": height, "origin": {"position": _v3(x0, y0), "orientation": quaternion(yaw)}},
            "data": np.asarray(grid.data, dtype=np.int8).reshape(-1)}


def tf(t: float, x: float, y: float, yaw: float, frame: str = ODOM_FRAME,
       child: str = BASE_FRAME) -> dict[str, Any]:
    """``tf2_msgs/msg/TFMessage`` with one transform, ``frame`` -> ``child``."""
    return {"transforms": [{"header": header(t, frame), "child_frame_id": child,
                            "transform": {"translation": _v3(x, y), "rotation": quaternion(yaw)}}]}


def joint_state(t: float, positions: tuple[float, float], velocities: tuple[float, float],
                frame: str = BASE_FRAME) -> dict[str, Any]:
    """``sensor_msgs/msg/JointState`` of the two wheels (rad, rad/s, forward positive)."""
    return {"header": header(t, frame), "name": list(WHEEL_JOINTS),
            "position": [float(p) for p in positions], "velocity": [float(v) for v in velocities],
            "effort": []}


def serial_line(t: float, line: str, hardware_id: str = "wcdrive") -> dict[str, Any]:
    """``diagnostic_msgs/msg/DiagnosticArray`` carrying one raw line from the board;
    level WARN (1) for ``ERR:``/``EVT:`` lines, OK (0) otherwise."""
    level = 1 if line.startswith(("ERR:", "EVT:")) else 0
    return {"header": header(t, ""), "status": [{"level": level, "name": "wcdrive/serial",
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
    """Writes ROS 2 messages into an MCAP file as Jazzy's rosbag2 MCAP storage writes
    one: profile ``ros2``; a ``ros2msg`` schema per type (its full definition, from the
    type store); a ``cdr`` channel per topic whose metadata holds
    ``offered_qos_profiles`` (``QOS``, in bag version 9's YAML) and
    ``topic_type_hash`` (RIHS01); zstd chunks; and at the end the ``rosbag2`` metadata
    record whose ``serialized_metadata`` is the bag's metadata (what metadata.yaml
    holds), so that rosbag2 reads the QoS as version 9's. ``log_time`` and
    ``publish_time`` are the messages' stamps."""

    def __init__(self, path: str | Path) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(path)
        self._file = self.path.open("wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=f"wcdrive (rosbag2 {ROS_DISTRO} layout)")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, Callable[[dict[str, Any]], bytes]]] = {}
        self._counts: dict[str, int] = {}
        self._first: int | None = None
        self._last = 0
        self._lock = threading.Lock()
        self._closed = False

    def _channel(self, topic: str) -> tuple[int, Callable[[dict[str, Any]], bytes]]:
        typename = TOPICS[topic]
        schema = self._schemas.get(typename)
        if schema is None:
            schema = self._schemas[typename] = self._writer.register_schema(
                typename, "ros2msg", msgdef(typename).encode())
        channel = self._writer.register_channel(topic, "cdr", schema, {
            "offered_qos_profiles": _yaml([qos(topic).rosbag2()]),
            "topic_type_hash": type_hash(typename)})
        encode = encoder(typename)
        self._channels[topic] = (channel, encode)
        self._counts[topic] = 0
        return channel, encode

    def publish(self, topic: str, message: dict[str, Any], log_time: float) -> None:
        """One message on ``topic`` (a key of ``TOPICS``)."""
        ns = max(0, round(log_time * 1e9))
        with self._lock:
            if self._closed:
                return
            channel, encode = self._channels.get(topic) or self._channel(topic)
            self._writer.add_message(channel, log_time=ns, data=encode(message), publish_time=ns)
            self._counts[topic] += 1
            self._first = ns if self._first is None else min(self._first, ns)
            self._last = max(self._last, ns)

    def metadata(self) -> dict[str, Any]:
        """The bag's metadata so far, as rosbag2 (version 9) writes it."""
        start = self._first or 0
        duration = max(0, self._last - start)
        count = sum(self._counts.values())
        return {
            "version": 9, "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration}, "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": TOPICS[topic], "serialization_format": "cdr",
                                    "offered_qos_profiles": [qos(topic).rosbag2()],
                                    "type_description_hash": type_hash(TOPICS[topic])},
                 "message_count": n} for topic, n in self._counts.items()],
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [{"path": self.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": count}],
            "custom_data": {}, "ros_distro": ROS_DISTRO,
        }

    def close(self) -> None:
        """Finishes the file (the rosbag2 metadata record, the summary and index). Safe
        to call twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.add_metadata("rosbag2", {"serialized_metadata": _yaml(self.metadata())})
            self._writer.finish()
            self._file.close()


def _yaml(value: Any) -> str:
    """``value`` as block-style YAML (keys in the order given), as yaml-cpp dumps it."""
    import yaml

    return str(yaml.safe_dump(value, default_flow_style=False, sort_keys=False)).rstrip("\n")


class LiveSink:
    """Serves the messages on Foxglove's WebSocket protocol (``foxglove-sdk``): open
    ``ws://host:port`` in Foxglove. Each topic is a channel with its ``ros2msg`` schema
    and CDR messages."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "wcdrive") -> None:
        import foxglove

        self._foxglove = foxglove
        self._context = foxglove.Context()
        self._channels: dict[str, Any] = {}
        self._encoders: dict[str, Callable[[dict[str, Any]], bytes]] = {}
        self._lock = threading.Lock()
        self._closed = False
        # Every channel before the server starts, so before any client: one made while a
        # client is connected is advertised before the server knows it, and a quick
        # subscribe to it is refused ("Unknown channel ID", foxglove-sdk 0.30).
        for topic in TOPICS:
            self._channel(topic)
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self._context)

    @property
    def port(self) -> int:
        """The port the server listens on (``port=0`` picks a free one)."""
        return int(self.server.port)

    def _channel(self, topic: str) -> tuple[Any, Callable[[dict[str, Any]], bytes]]:
        typename = TOPICS[topic]
        channel = self._channels.get(topic)
        if channel is None:
            schema = self._foxglove.Schema(name=typename, encoding="ros2msg", data=msgdef(typename).encode())
            channel = self._foxglove.Channel(topic, schema=schema, message_encoding="cdr",
                                             context=self._context)
            self._channels[topic] = channel
            self._encoders[topic] = encoder(typename)
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
        self._board: Simulated | None = None
        self._gyro_seen = 0

    def attach(self, chair: Any, board: Simulated | None = None) -> None:
        """Subscribes to ``chair``'s ticks; ``board``: the simulated board, if any
        (``wcdrive.transports.port.simulation_of``)."""
        self._chair, self._board = chair, board
        chair.on_telemetry(self._tick)

    def wrote(self, data: bytes) -> None:
        """Bytes the host wrote: a velocity or wheel command is a ``/cmd_vel``."""
        t = self._monotonic() + self._wall
        command = find_motion(data)
        if isinstance(command, VelocityCommand):
            self.sink.publish("/cmd_vel", twist_stamped(t, command.linear, command.angular), t)
        elif isinstance(command, WheelCommand):
            r, left = command.right, command.left
            self.sink.publish("/cmd_vel", twist_stamped(t, 0.5 * self._radius * (r + left),
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
            self._simulated(chair, self._board)

    def _simulated(self, chair: Any, sim: Simulated) -> None:
        truth = sim.ground_truth()
        if truth is None:
            return
        # the gyro keeps its newest samples only: count every one it took
        new = sim.gyro_samples(self._gyro_seen)
        self._gyro_seen = new.total
        clock = chair.board_clock
        t = clock.to_host(truth.time) + self._wall
        self.sink.publish("/ground_truth", odometry(t, truth.x, truth.y, truth.heading, truth.linear,
                                                    truth.angular), t)
        variance = math.radians(sim.gyro_noise_dps) ** 2
        for ts, rate in new.samples:
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
    def recording(self) -> Recording | None:
        """The recording of the port it wraps (``recording_of``: ``connect(url,
        record=True)``), else None."""
        return recording_of(self.port)

    def on_sent(self, data: bytes) -> None:
        """Publishes what the host wrote."""
        self.publisher.wrote(data)

    def on_read(self, data: bytes) -> bytes:
        """Publishes what the host read (when there is any) and passes it on."""
        if data:
            self.publisher.read(data)
        return data
