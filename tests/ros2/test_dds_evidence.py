"""The bridge on a ROS 2 graph, seen from outside: an independent DDS participant in
another process (``dds_peer.py``: its own types, parsed from the ``.msg`` text; its
own Cyclone configuration) subscribes to every topic and drives the simulated chair
around a square with a 20 Hz ``/cmd_vel`` stream of TwistStamped buffers built byte by
byte as a Jazzy publisher sends them. The bridge runs here, so its ``/odom`` can be
held to ``chair.odometry`` tick by tick.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rosbags.typesys import Stores, get_typestore

import wcdrive
from tests.ros2.conftest import fresh_domain, run_peer
from tests.ros2.dds_peer import twist_stamped
from wcdrive.ros2.dds import types
from wcdrive.ros2.dds.graph import RosNode
from wcdrive.ros2.dds.node import ChairNode, ImuTap, Options

#: What ROS 2 gives each endpoint: (reliable, transient local, depth). rclcpp's
#: SystemDefaultsQoS/QoS(10) for data, SensorDataQoS for the IMU, tf2_ros' broadcasters
#: for /tf (100) and /tf_static (transient local, 1), rmw_dds_common's graph topic;
#: /cmd_vel read best effort, so that best-effort writers (Jazzy's controller stack)
#: match as reliable ones do.
EXPECTED_QOS = {
    ("pub", "rt/odom", "nav_msgs::msg::dds_::Odometry_"): (True, False, 10),
    ("pub", "rt/tf", "tf2_msgs::msg::dds_::TFMessage_"): (True, False, 100),
    ("pub", "rt/tf_static", "tf2_msgs::msg::dds_::TFMessage_"): (True, True, 1),
    ("pub", "rt/joint_states", "sensor_msgs::msg::dds_::JointState_"): (True, False, 10),
    ("pub", "rt/imu", "sensor_msgs::msg::dds_::Imu_"): (False, False, 5),
    ("pub", "rt/diagnostics", "diagnostic_msgs::msg::dds_::DiagnosticArray_"): (True, False, 10),
    ("pub", "rt/scan", "sensor_msgs::msg::dds_::LaserScan_"): (False, False, 5),
    ("pub", "ros_discovery_info",
     "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"): (True, True, 1),
    ("sub", "rt/cmd_vel", "geometry_msgs::msg::dds_::TwistStamped_"): (False, False, 10),
    ("sub", "rt/estop", "std_msgs::msg::dds_::Bool_"): (True, False, 10),
    ("sub", "rt/estop_reset", "std_msgs::msg::dds_::Empty_"): (True, False, 10),
}
#: RIHS01 hashes of ROS 2 Jazzy as published outside rosbags (``ros2 topic info -v`` on
#: a Jazzy system, rosidl's golden-hash tests, rmw_zenoh key expressions quoted in
#: public repositories): an anchor independent of the type store.
GOLDEN = {
    "geometry_msgs/msg/TwistStamped":
        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64",
    "nav_msgs/msg/Odometry": "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    "sensor_msgs/msg/Imu": "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b",
    "diagnostic_msgs/msg/DiagnosticArray":
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    "std_msgs/msg/Bool": "RIHS01_feb91e995ff9ebd09c0cb3d2aed18b11077585839fb5db80193b62d74528f6c9",
}


def ros_type(dds_type: str) -> str:
    """``pkg::msg::dds_::Msg_`` -> ``pkg/msg/Msg``."""
    package, kind, _, message = dds_type.split("::")
    return f"{package}/{kind}/{message[:-1]}"


class FakeScan:
    """A ``ScanSource``: eight ranges of 1.5 m in frame ``laser``, at most 5 a second."""

    def __init__(self) -> None:
        self.last = 0.0

    def scan(self) -> dict[str, Any] | None:
        now = time.time()
        if now - self.last < 0.2:
            return None
        self.last = now
        return {"header": {"stamp": {"sec": int(now), "nanosec": int(now % 1 * 1e9)}, "frame_id": "laser"},
                "angle_min": -math.pi / 4, "angle_max": math.pi / 4, "angle_increment": math.pi / 14,
                "range_min": 0.1, "range_max": 8.0, "ranges": [1.5] * 8}


@pytest.fixture(scope="module")
def square() -> Iterator[dict[str, Any]]:
    """The bridge on ``sim://`` in real time here, as a board runs; the peer drives the square. The peer's
    summary, the odometry each tick had here (by stamp) and the gate's counts. (At twice real time a
    loaded machine's pause of 250 ms in the peer's 20 Hz stream was the board's 500 ms watchdog, and
    the rest of the square was refused until a neutral command: the suite under ``-n 2``.)"""
    domain = fresh_domain()
    tap = ImuTap()
    chair = wcdrive.connect("sim://", ros=tap)
    node = ChairNode(chair, RosNode("wcdrive", domain=domain), Options(scan=FakeScan()), imu=tap)
    here: dict[tuple[int, int], Any] = {}
    try:
        node.start()

        def record(tel: Any) -> None:
            ns = round(node.stamp(tel) * 1e9)
            here[(ns // 1_000_000_000, ns % 1_000_000_000)] = chair.odometry

        chair.on_telemetry(record)
        peer = run_peer(domain, "square")
        counts = dict(node.gate.counts)
    finally:
        node.close()
        chair.close()
    yield {"peer": peer, "here": here, "counts": counts}


def test_the_chair_drives_a_square_from_a_20hz_cmd_vel_stream(square: dict[str, Any]) -> None:
    peer = square["peer"]
    assert peer["discovered"], peer
    assert len(peer["legs"]) == 8, peer["legs"]
    odom = peer["odom"]
    x, y, heading = odom[-1][2], odom[-1][3], odom[-1][4]
    assert max(o[2] for o in odom) > 0.25 and max(o[3] for o in odom) > 0.25, "never left the start"
    assert math.hypot(x, y) < 0.12, (x, y)                      # back at the start
    assert abs(abs(heading) - 2 * math.pi) < 0.5 or abs(heading) < 0.5, heading
    assert odom[-1][5] == 0.0 and odom[-1][6] == 0.0, "not stopped at the end"
    counts = square["counts"]
    assert counts.get("accepted", 0) >= 150, counts             # 20 Hz for ~10 s and more
    assert sum(n for k, n in counts.items() if k != "accepted") == 0, counts


def test_odom_is_chair_odometry_tick_by_tick(square: dict[str, Any]) -> None:
    here, odom = square["here"], square["peer"]["odom"]
    matched = 0
    for sec, nanosec, x, y, yaw, linear, angular, cov0, frame, child in odom:
        estimate = here.get((sec, nanosec))
        if estimate is None:
            continue                   # a tick before the recorder was in place
        matched += 1
        assert (x, y, linear, angular) == (estimate.pose.x, estimate.pose.y, estimate.linear,
                                           estimate.angular)
        turned = yaw - estimate.pose.theta                  # the quaternion wraps, theta does not
        assert abs(math.remainder(turned, 2 * math.pi)) < 1e-9, (yaw, estimate.pose.theta)
        assert cov0 == estimate.pose_covariance[0, 0]
        assert (frame, child) == ("odom", "base_link")
    assert matched >= len(odom) - 5 and matched > 100, (matched, len(odom))


def test_user_data_carries_jazzy_rihs01_type_hashes(square: dict[str, Any]) -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    endpoints = square["peer"]["endpoints"]
    assert len(endpoints) == len(EXPECTED_QOS)
    for e in endpoints:
        name = ros_type(e["type"])
        assert e["user_data"] == f"typehash={store.hash_rihs01(name)};", e
        if name in GOLDEN:
            assert e["user_data"] == f"typehash={GOLDEN[name]};", e
    assert {ros_type(e["type"]) for e in endpoints} >= set(GOLDEN)


def test_each_endpoint_has_its_ros2_qos_and_name(square: dict[str, Any]) -> None:
    seen = {(e["kind"], e["topic"], e["type"]): (e["reliable"], e["transient_local"], e["depth"])
            for e in square["peer"]["endpoints"]}
    assert seen == EXPECTED_QOS


def test_every_topic_arrives(square: dict[str, Any]) -> None:
    peer = square["peer"]
    counts = peer["counts"]
    assert all(counts[t] > 0 for t in ("rt/odom", "rt/tf", "rt/tf_static", "rt/joint_states", "rt/imu",
                                       "rt/diagnostics", "ros_discovery_info")), counts
    # one message each per tick (the peer's last read may fall between two of them)
    assert abs(counts["rt/tf"] - counts["rt/odom"]) <= 2, counts
    assert abs(counts["rt/joint_states"] - counts["rt/odom"]) <= 2, counts
    assert counts["rt/imu"] > 5 * counts["rt/odom"]           # 400 Hz gyro, 20 Hz ticks
    assert peer["tf"] == [["odom", "base_link"]]
    assert peer["tf_static"] == [["base_link", "imu_link"]]
    assert peer["joint_names"] == ["left_wheel_joint", "right_wheel_joint"]
    assert counts["rt/scan"] >= 10                             # the scan source plugs in
    assert peer["scans"][-1][0] == "laser" and peer["scans"][-1][1] == [1.5] * 8
    assert peer["diagnostics"] == ["wcdrive: TLM", "wcdrive: battery", "wcdrive: cmd_vel",
                                   "wcdrive: drive profile", "wcdrive: e-stop", "wcdrive: faults",
                                   "wcdrive: link", "wcdrive: motor heat"]
    assert int(peer["cmd_vel_diag"][-1]["accepted"]) > 100


def test_ros_discovery_info_names_the_node_and_its_endpoints(square: dict[str, Any]) -> None:
    """What ``ros2 node list`` and ``ros2 node info`` read: node ``/wcdrive``, its
    participant's GID and the GIDs of its readers and its writers on ``rt/`` topics,
    each the DDS GUID the peer's own discovery gives that entity."""
    endpoints = square["peer"]["endpoints"]
    namespace, name, readers, writers, gid = square["peer"]["nodes"][-1]
    assert (namespace, name) == ("/", "wcdrive")
    assert {e["participant"] for e in endpoints} == {gid}
    assert readers == sorted(e["key"] for e in endpoints if e["kind"] == "sub")
    assert writers == sorted(e["key"] for e in endpoints
                             if e["kind"] == "pub" and e["topic"].startswith("rt/"))
    assert len(readers) == 3 and len(writers) == 7


def test_twist_stamped_is_byte_for_byte_a_jazzy_publishers() -> None:
    """The bridge's generated type writes, and reads, the buffer built by hand from the
    definition (``dds_peer.twist_stamped``), which the peer drives the square with."""
    buffer = twist_stamped(1_700_000_000, 123_456_789, "base_link", (0.5, 0.0, 0.0), (0.0, 0.0, -0.25))
    message = types.build("geometry_msgs/msg/TwistStamped", {
        "header": {"stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789}, "frame_id": "base_link"},
        "twist": {"linear": {"x": 0.5}, "angular": {"z": -0.25}}})
    assert message.serialize(use_version_2=False) == buffer
    back = types.to_dict("geometry_msgs/msg/TwistStamped",
                         types.idl_class("geometry_msgs/msg/TwistStamped").deserialize(buffer))
    assert back["twist"]["angular"]["z"] == -0.25 and back["header"]["frame_id"] == "base_link"
    assert len(buffer) == 4 + 8 + 4 + 10 + 2 + 48      # header, stamp, string, pad to 8, 6 doubles


def test_the_peers_own_types_write_the_hand_built_buffer(square: dict[str, Any]) -> None:
    """The peer's types (from the .msg text) agree with the hand-built buffer too."""
    assert square["peer"]["hand_built_equals_generated"]


def test_twist_cmd_vel_and_clock_when_faster_than_real_time() -> None:
    """``--twist``: plain ``geometry_msgs/Twist`` drives; with ``sim_time`` (a board at
    twice real time) ``/clock`` runs at the board's pace and every stamp is on it."""
    domain = fresh_domain()
    tap = ImuTap()
    chair = wcdrive.connect("sim://?speed=2", ros=tap)
    node = ChairNode(chair, RosNode("wcdrive", domain=domain), Options(twist=True, sim_time=True), imu=tap)
    try:
        node.start()
        peer = run_peer(domain, "twist")
        counts = dict(node.gate.counts)
    finally:
        node.close()
        chair.close()
    assert peer["speed"] > 0.2 and counts["accepted"] >= 20, (peer["speed"], counts)
    clock = peer["clock"]
    assert len(clock) >= 20
    (board0, wall0), (board1, wall1) = clock[0], clock[-1]
    assert all(b1 >= b0 for (b0, _), (b1, _) in itertools.pairwise(clock))
    assert 1.5 < (board1 - board0) / (wall1 - wall0) < 2.5        # the board's pace, not the wall's
    assert board1 < 1000.0                                         # board seconds, not the epoch
    stamps = peer["odom_stamps"]                                   # /odom on the same clock
    assert all(board0 - 0.5 < s < board1 + 0.5 for s in stamps[-20:]), (stamps[-20:], board0, board1)


def test_the_eddie_is_driven_the_same_way() -> None:
    """``eddie+sim://`` behind the same node: the peer's TwistStamped stream drives it."""
    domain = fresh_domain()
    eddie = wcdrive.connect("eddie+sim://")
    node = ChairNode(eddie, RosNode("wcdrive", domain=domain), Options())
    try:
        node.start()
        run_peer(domain, "forward", "--seconds", "2")
        moved = eddie.odometry.pose.x
        counts = dict(node.gate.counts)
    finally:
        node.close()
        eddie.close()
    assert moved > 0.2, moved                       # 0.3 m/s for 2 s, less the ramp
    assert counts["accepted"] >= 25, counts         # ("refused": a poll the board missed)
