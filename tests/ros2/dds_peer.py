"""An independent ROS 2 participant for the bridge's evidence tests; it never imports
wcdrive.

Its message types are generated here from the ``.msg`` text of ROS 2 Jazzy (``MSGS``,
copied from the ROS 2 packages' ``msg/`` files, comments left out), by a parser of
its own, not from rosbags and not from ``wcdrive.ros2.dds``. It joins the domain with a
Cyclone configuration of its own, then, by ``--mode``:

- ``square``: subscribes to every topic the bridge publishes, records the bridge's
  endpoints as DDS discovery shows them (topic, type name, QoS, USER_DATA), then
  drives a 0.5 m square closed on ``/odom``, publishing ``/cmd_vel`` at 20 Hz as raw
  CDR buffers built byte by byte from the TwistStamped definition (``twist_stamped``),
  and ends stopped. Prints a JSON summary.
- ``bad``: publishes stale, non-finite and out-of-range TwistStamped, then a burst of
  good ones, then ``/estop``; prints what ``/odom`` did.
- ``forward``: sends 0.3 m/s straight at 20 Hz for ``--seconds`` s, whoever listens.
- ``twist``: ``/cmd_vel`` as plain ``geometry_msgs/Twist`` (0.3 m/s for 2 s) to a
  bridge run with ``--twist`` and ``/clock``; records ``/clock`` with the wall time of
  each arrival.
- ``discover``: only waits for the bridge's ``rt/odom`` writer; prints whether it saw it.

    python dds_peer.py --domain 117 --mode square [--address 127.0.0.1 | 192.0.2.2]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import struct
import sys
import time
from typing import Any

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import make_idl_struct, types
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

#: ROS 2 Jazzy's message definitions (``pkg/msg/Name.msg``), comments left out.
MSGS = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "std_msgs/msg/Bool": "bool data",
    "std_msgs/msg/Empty": "",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1",
    "geometry_msgs/msg/Pose": "Point position\nQuaternion orientation",
    "geometry_msgs/msg/PoseWithCovariance": "Pose pose\nfloat64[36] covariance",
    "geometry_msgs/msg/Twist": "Vector3  linear\nVector3  angular",
    "geometry_msgs/msg/TwistStamped": "std_msgs/Header header\nTwist twist",
    "geometry_msgs/msg/TwistWithCovariance": "Twist twist\nfloat64[36] covariance",
    "geometry_msgs/msg/Transform": "Vector3 translation\nQuaternion rotation",
    "geometry_msgs/msg/TransformStamped": ("std_msgs/Header header\nstring child_frame_id\n"
                                           "Transform transform"),
    "nav_msgs/msg/Odometry": ("std_msgs/Header header\nstring child_frame_id\n"
                              "geometry_msgs/PoseWithCovariance pose\n"
                              "geometry_msgs/TwistWithCovariance twist"),
    "tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms",
    "sensor_msgs/msg/JointState": ("std_msgs/Header header\nstring[] name\n"
                                   "float64[] position\nfloat64[] velocity\nfloat64[] effort"),
    "sensor_msgs/msg/Imu": ("std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
                            "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
                            "float64[9] angular_velocity_covariance\n"
                            "geometry_msgs/Vector3 linear_acceleration\n"
                            "float64[9] linear_acceleration_covariance"),
    "sensor_msgs/msg/LaserScan": ("std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\n"
                                  "float32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\n"
                                  "float32 range_min\nfloat32 range_max\nfloat32[] ranges\n"
                                  "float32[] intensities"),
    "diagnostic_msgs/msg/KeyValue": "string key\nstring value",
    "diagnostic_msgs/msg/DiagnosticStatus": ("byte OK=0\nbyte WARN=1\nbyte ERROR=2\n"
                                             "byte STALE=3\nbyte level\nstring name\nstring message\n"
                                             "string hardware_id\n"
                                             "KeyValue[] values"),
    "diagnostic_msgs/msg/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status",
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock",
    "rmw_dds_common/msg/Gid": "char[16] data",
    "rmw_dds_common/msg/NodeEntitiesInfo": ("string<=256 node_namespace\nstring<=256 node_name\n"
                                            "Gid[] reader_gid_seq\nGid[] writer_gid_seq"),
    "rmw_dds_common/msg/ParticipantEntitiesInfo": "Gid gid\nNodeEntitiesInfo[] node_entities_info_seq",
}
PRIMITIVES: dict[str, Any] = {
    "bool": bool, "byte": types.uint8, "char": types.uint8, "int8": types.int8, "uint8": types.uint8,
    "int16": types.int16, "uint16": types.uint16, "int32": types.int32, "uint32": types.uint32,
    "int64": types.int64, "uint64": types.uint64, "float32": types.float32, "float64": types.float64,
    "string": str,
}
_CLASSES: dict[str, Any] = {}
_STR: Any = types.bounded_str          # generic at run time; mypy does not see it
_ARRAY: Any = types.array
_SEQUENCE: Any = types.sequence


def parse(name: str) -> list[tuple[str, str]]:
    """(type, field) pairs of a .msg text; constants (``TYPE NAME=VALUE``) are skipped."""
    out = []
    for line in MSGS[name].splitlines():
        line = line.split("#")[0].strip()
        if not line or re.match(r"^\S+\s+\w+\s*=", line):
            continue
        kind, field = line.split()[:2]
        out.append((kind, field))
    return out


def resolve(kind: str, package: str) -> Any:
    m = re.fullmatch(r"([\w/]+?)(<=\d+)?(\[(<=)?(\d*)\])?", kind)
    assert m, kind
    base, bound, array, upto, size = m.groups()
    if base in PRIMITIVES:
        element: Any = PRIMITIVES[base]
        if base == "string" and bound:
            element = _STR[int(bound[2:])]
    else:
        full = base if "/" in base else ("std_msgs/Header" if base == "Header" else f"{package}/{base}")
        pkg, msg = full.split("/")
        element = idl(f"{pkg}/msg/{msg}")
    if array is None:
        return element
    if size and not upto:
        return _ARRAY[element, int(size)]
    return _SEQUENCE[element, int(size)] if size else _SEQUENCE[element]


def idl(name: str) -> Any:
    """The cyclonedds class of ``pkg/msg/Name`` from its .msg text (rosidl's rules:
    ``pkg::msg::dds_::Name_``, an empty message gets one uint8 member)."""
    if name not in _CLASSES:
        package = name.split("/")[0]
        fields = {f: resolve(k, package) for k, f in parse(name)}
        if not fields:
            fields = {"structure_needs_at_least_one_member": types.uint8}
        pkg, sub, msg = name.split("/")
        _CLASSES[name] = make_idl_struct(msg, f"{pkg}::{sub}::dds_::{msg}_", fields)
    return _CLASSES[name]


def twist_stamped(sec: int, nanosec: int, frame: str, linear: tuple[float, float, float],
                  angular: tuple[float, float, float]) -> bytes:
    """A TwistStamped as a ROS 2 Jazzy publisher puts it on the wire, byte by byte:
    the encapsulation header (CDR, little endian: 00 01, options 00 00), then plain CDR
    (XCDR1) with each primitive aligned to its size from the start of the body."""
    body = bytearray(struct.pack("<iI", sec, nanosec))
    text = frame.encode() + b"\0"
    body += struct.pack("<I", len(text)) + text
    body += b"\0" * (-len(body) % 8)                # float64 aligns to 8
    body += struct.pack("<6d", *linear, *angular)
    return b"\x00\x01\x00\x00" + bytes(body)


def config(address: str) -> str:
    """This peer's Cyclone configuration: the one interface of ``address``, unicast."""
    return ("<CycloneDDS><Domain id='any'><General><Interfaces>"
            f"<NetworkInterface address='{address}'/></Interfaces><AllowMulticast>false</AllowMulticast>"
            "</General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
            "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
            f"<Peers><Peer address='{address}'/></Peers></Discovery></Domain></CycloneDDS>")


def qos(reliable: bool, transient: bool = False, depth: int = 10) -> Qos:
    return Qos(Policy.Reliability.Reliable(100_000_000) if reliable else Policy.Reliability.BestEffort,
               Policy.Durability.TransientLocal if transient else Policy.Durability.Volatile,
               Policy.History.KeepLast(depth), Policy.DataRepresentation(use_cdrv0_representation=True))


def describe(sample: Any) -> dict[str, Any]:
    q = sample.qos
    reliability = q[Policy.Reliability]
    durability = q[Policy.Durability]
    history = q[Policy.History]
    user = q[Policy.Userdata] if Policy.Userdata in q else None
    return {"topic": sample.topic_name, "type": sample.type_name, "key": sample.key.bytes.hex(),
            "participant": sample.participant_key.bytes.hex(),
            "reliable": not isinstance(reliability, type(Policy.Reliability.BestEffort))
            and "BestEffort" not in repr(reliability),
            "transient_local": "TransientLocal" in repr(durability),
            "depth": getattr(history, "depth", None),
            "user_data": user.data.decode() if user is not None else ""}


class Peer:
    def __init__(self, domain: int, address: str) -> None:
        self.domain = Domain(domain, config(address))
        self.dp = DomainParticipant(domain)
        self.topics: dict[str, Any] = {}
        self.readers: dict[str, Any] = {}
        self.received: dict[str, list[Any]] = {}

    def topic(self, name: str, msgtype: str) -> Any:
        if name not in self.topics:
            self.topics[name] = Topic(self.dp, name, idl(msgtype))
        return self.topics[name]

    def read(self, name: str, msgtype: str, q: Qos) -> None:
        self.readers[name] = DataReader(self.dp, self.topic(name, msgtype), qos=q)
        self.received[name] = []

    def poll(self) -> None:
        for name, reader in self.readers.items():
            self.received[name] += [s for s in reader.take(N=256) if s.sample_info.valid_data]

    def endpoints(self) -> list[dict[str, Any]]:
        own = self.dp.get_guid()
        out = []
        for kind, builtin in (("pub", BuiltinTopicDcpsPublication), ("sub", BuiltinTopicDcpsSubscription)):
            reader = BuiltinDataReader(self.dp, builtin)
            for s in reader.read(N=256):
                if s.participant_key != own:
                    out.append({"kind": kind, **describe(s)})
        return out

    def wait_for(self, topic: str, kind: str, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if any(e["topic"] == topic and e["kind"] == kind for e in self.endpoints()):
                return True
            self.poll()
            time.sleep(0.05)
        return False


def yaw(odom: Any) -> float:
    q = odom.pose.pose.orientation
    return 2.0 * math.atan2(q.z, q.w)


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def square(peer: Peer, writer: Any, side: float = 0.3, timeout: float = 40.0) -> list[str]:
    """Drives a square closed on /odom, /cmd_vel at 20 Hz as raw Jazzy CDR: four times
    straight ``side`` m toward the next corner (heading held), then a left turn to the
    next multiple of 90 degrees from the start, each leg ended stopped. Returns the legs
    it finished, with the distance or heading error left."""
    from cyclonedds._clayer import ddspy_write

    def send(linear: float, angular: float) -> None:
        wall = time.time()
        ddspy_write(writer._ref, twist_stamped(int(wall), int((wall % 1) * 1e9), "base_link",
                                               (linear, 0.0, 0.0), (0.0, 0.0, angular)))

    end = time.monotonic() + timeout

    def pose() -> tuple[float, float, float, float, float]:
        while not peer.received["rt/odom"]:
            if time.monotonic() > end:
                raise TimeoutError("no /odom from the bridge")
            peer.poll()
            time.sleep(0.01)
        o = peer.received["rt/odom"][-1]
        return (o.pose.pose.position.x, o.pose.pose.position.y, yaw(o), o.twist.twist.linear.x,
                o.twist.twist.angular.z)

    try:
        x0, y0, h0, _, _ = pose()
    except TimeoutError:
        return []
    started = time.monotonic()
    legs: list[str] = []
    for corner in range(4):
        heading = h0 + corner * math.pi / 2
        corners = [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side)]
        cx, cy = corners[(corner + 1) % 4]
        gx = x0 + cx * math.cos(h0) - cy * math.sin(h0)
        gy = y0 + cx * math.sin(h0) + cy * math.cos(h0)
        for kind in ("straight", "turn"):
            target = heading + (math.pi / 2 if kind == "turn" else 0.0)
            while time.monotonic() < end:
                peer.poll()
                x, y, h, v, w = pose()
                error = wrap(target - h)
                along = (gx - x) * math.cos(heading) + (gy - y) * math.sin(heading)
                if kind == "straight":
                    if along <= 0.005:
                        break
                    command = (min(0.5, max(0.1, 1.5 * along)), max(-0.5, min(0.5, 2.0 * error)))
                else:
                    if abs(error) <= 0.12:            # it coasts about 0.15 rad
                        break
                    command = (0.0, math.copysign(min(1.0, max(0.3, 2.0 * abs(error))), error))
                send(*command)
                time.sleep(0.05)                                    # 20 Hz
            settle = time.monotonic() + 0.4
            while time.monotonic() < min(settle, end):              # stop, then measure
                send(0.0, 0.0)
                time.sleep(0.05)
                peer.poll()
                x, y, h, v, w = pose()
                if abs(v) < 0.01 and abs(w) < 0.02:
                    break
            left = (gx - x) * math.cos(heading) + (gy - y) * math.sin(heading)
            legs.append(f"{kind} {left if kind == 'straight' else wrap(target - h):+.3f} "
                        f"at {time.monotonic() - started:.1f} s")
    # Stop and wait for the chair to be at rest (its odom's twist exactly 0): 0.5 s on a
    # quiet machine; up to 3 s more when the simulation runs behind the wall clock.
    rest = time.monotonic() + 3.5
    for n in range(70):
        send(0.0, 0.0)
        time.sleep(0.05)
        peer.poll()
        _, _, _, v, w = pose()
        if (n >= 9 and v == 0.0 and w == 0.0) or time.monotonic() > rest:
            break
    return legs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--mode", choices=("square", "bad", "discover", "forward", "twist"), default="square")
    ap.add_argument("--seconds", type=float, default=10.0, help="forward: how long to send")
    ap.add_argument("--address", default="127.0.0.1")
    ap.add_argument("--discovery-timeout", type=float, default=20.0)
    args = ap.parse_args()
    peer = Peer(args.domain, args.address)
    result: dict[str, Any] = {}
    if args.mode == "discover":
        result["seen"] = peer.wait_for("rt/odom", "pub", args.discovery_timeout)
        print(json.dumps(result))
        return
    reliable = qos(True)
    peer.read("rt/odom", "nav_msgs/msg/Odometry", reliable)
    peer.read("rt/tf", "tf2_msgs/msg/TFMessage", reliable)
    peer.read("rt/tf_static", "tf2_msgs/msg/TFMessage", qos(True, transient=True, depth=1))
    peer.read("rt/joint_states", "sensor_msgs/msg/JointState", reliable)
    peer.read("rt/imu", "sensor_msgs/msg/Imu", qos(False, depth=50))
    peer.read("rt/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", reliable)
    peer.read("rt/scan", "sensor_msgs/msg/LaserScan", qos(False, depth=5))
    peer.read("ros_discovery_info", "rmw_dds_common/msg/ParticipantEntitiesInfo",
              qos(True, transient=True, depth=1))
    if args.mode == "twist":
        print(json.dumps(twist_run(peer, reliable, args.discovery_timeout)))
        return
    writer = DataWriter(self_dp := peer.dp, peer.topic("rt/cmd_vel", "geometry_msgs/msg/TwistStamped"),
                        qos=reliable)
    estop = DataWriter(self_dp, peer.topic("rt/estop", "std_msgs/msg/Bool"), qos=reliable)
    reset = DataWriter(self_dp, peer.topic("rt/estop_reset", "std_msgs/msg/Empty"), qos=reliable)
    result["discovered"] = (peer.wait_for("rt/cmd_vel", "sub", args.discovery_timeout)
                            and peer.wait_for("rt/odom", "pub", args.discovery_timeout))
    deadline = time.monotonic() + args.discovery_timeout
    while writer.get_publication_matched_status().current_count < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    sample = idl("geometry_msgs/msg/TwistStamped")
    built = twist_stamped(1, 2, "base_link", (0.5, 0.0, 0.0), (0.0, 0.0, 0.25))
    generated = sample(header=idl("std_msgs/msg/Header")(stamp=idl("builtin_interfaces/msg/Time")(1, 2),
                                                         frame_id="base_link"),
                       twist=idl("geometry_msgs/msg/Twist")(
                           linear=idl("geometry_msgs/msg/Vector3")(0.5, 0.0, 0.0),
                           angular=idl("geometry_msgs/msg/Vector3")(0.0, 0.0, 0.25)))
    result["hand_built_equals_generated"] = generated.serialize(use_version_2=False) == built
    result["hand_built_hex"] = built.hex()
    if args.mode == "forward":
        forward(writer, args.seconds)
    elif args.mode == "square":
        result["legs"] = square(peer, writer)
    else:
        result.update(bad_commands(peer, writer, estop, reset))
    time.sleep(0.3)
    peer.poll()
    result["endpoints"] = peer.endpoints()
    r = peer.received
    result["counts"] = {k: len(v) for k, v in r.items()}
    result["odom"] = [[o.header.stamp.sec, o.header.stamp.nanosec, o.pose.pose.position.x,
                       o.pose.pose.position.y, yaw(o), o.twist.twist.linear.x, o.twist.twist.angular.z,
                       o.pose.covariance[0], o.header.frame_id, o.child_frame_id] for o in r["rt/odom"]]
    result["tf"] = sorted({(t.header.frame_id, t.child_frame_id) for m in r["rt/tf"] for t in m.transforms})
    result["tf_static"] = sorted({(t.header.frame_id, t.child_frame_id)
                                  for m in r["rt/tf_static"] for t in m.transforms})
    result["joint_names"] = sorted({n for m in r["rt/joint_states"] for n in m.name})
    result["imu_rates"] = [m.angular_velocity.z for m in r["rt/imu"]][-5:]
    result["scans"] = [[m.header.frame_id, list(m.ranges), m.angle_increment] for m in r["rt/scan"]][-1:]
    result["diagnostics"] = sorted({s.name for m in r["rt/diagnostics"] for s in m.status})
    result["cmd_vel_diag"] = [{kv.key: kv.value for kv in s.values} for m in r["rt/diagnostics"]
                              for s in m.status if s.name == "wcdrive: cmd_vel"][-1:]
    result["nodes"] = [[n.node_namespace, n.node_name, sorted(bytes(g.data).hex() for g in n.reader_gid_seq),
                        sorted(bytes(g.data).hex() for g in n.writer_gid_seq), bytes(info.gid.data).hex()]
                       for info in r["ros_discovery_info"] for n in info.node_entities_info_seq]
    print(json.dumps(result))


def twist_run(peer: Peer, reliable: Qos, discovery_timeout: float) -> dict[str, Any]:
    """Plain Twist commands; /odom's speed, /clock with arrival times, /odom's stamps."""
    peer.read("rt/odom", "nav_msgs/msg/Odometry", reliable)
    clock = DataReader(peer.dp, peer.topic("rt/clock", "rosgraph_msgs/msg/Clock"), qos=qos(False, depth=1))
    writer = DataWriter(peer.dp, peer.topic("rt/cmd_vel", "geometry_msgs/msg/Twist"), qos=reliable)
    deadline = time.monotonic() + discovery_timeout
    while writer.get_publication_matched_status().current_count < 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    vector, twist = idl("geometry_msgs/msg/Vector3"), idl("geometry_msgs/msg/Twist")
    clocks: list[tuple[float, float]] = []
    end = time.monotonic() + 2.0
    while time.monotonic() < end:
        writer.write(twist(linear=vector(0.3, 0.0, 0.0), angular=vector(0.0, 0.0, 0.0)))
        peer.poll()
        clocks += [(c.clock.sec + c.clock.nanosec * 1e-9, time.monotonic()) for c in clock.take(N=64)
                   if c.sample_info.valid_data]
        time.sleep(0.05)
    odoms = peer.received["rt/odom"]
    return {"speed": max((o.twist.twist.linear.x for o in odoms), default=-1.0), "clock": clocks,
            "odom_stamps": [o.header.stamp.sec + o.header.stamp.nanosec * 1e-9 for o in odoms]}


def forward(writer: Any, seconds: float) -> None:
    from cyclonedds._clayer import ddspy_write

    print("sending", flush=True, file=sys.stderr)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        wall = time.time()
        ddspy_write(writer._ref, twist_stamped(int(wall), int((wall % 1) * 1e9), "base_link",
                                               (0.3, 0.0, 0.0), (0.0, 0.0, 0.0)))
        time.sleep(0.05)


def bad_commands(peer: Peer, writer: Any, estop: Any, reset: Any) -> dict[str, Any]:
    """Stale, non-finite and out-of-range commands, each for 0.6 s at 20 Hz, then good
    ones, then /estop and good ones again, then /estop_reset and good ones: the
    largest /odom speed of the last half second of each."""
    from cyclonedds._clayer import ddspy_write

    def send(linear: float, angular: float, age: float = 0.0, seconds: float = 1.0) -> float:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            wall = time.time() - age
            ddspy_write(writer._ref, twist_stamped(int(wall), int((wall % 1) * 1e9), "base_link",
                                                   (linear, 0.0, 0.0), (0.0, 0.0, angular)))
            peer.poll()
            time.sleep(0.05)
        odoms = peer.received["rt/odom"]
        return max(abs(o.twist.twist.linear.x) for o in odoms[-10:]) if odoms else -1.0

    out = {"stale": send(0.4, 0.0, age=5.0, seconds=0.6), "nan": send(float("nan"), 0.0, seconds=0.6),
           "inf": send(0.0, float("inf"), seconds=0.6), "too_fast": send(50.0, 0.0, seconds=0.6),
           "good": send(0.4, 0.0, seconds=1.5)}
    estop.write(idl("std_msgs/msg/Bool")(data=True))
    time.sleep(0.2)
    send(0.0, 0.0, seconds=0.2)
    out["after_estop"] = send(0.4, 0.0, seconds=1.0)
    print("estop held", flush=True, file=sys.stderr)
    time.sleep(0.5)                                         # the test reads the latch here
    reset.write(idl("std_msgs/msg/Empty")(structure_needs_at_least_one_member=0))
    send(0.0, 0.0, seconds=1.0)                             # the board resets once parked
    out["after_reset"] = send(0.4, 0.0, seconds=1.5)
    return out


if __name__ == "__main__":
    main()
