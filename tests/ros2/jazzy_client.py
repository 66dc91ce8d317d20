"""A stock ROS 2 Jazzy client of the bridge: rclpy on Fast DDS, run with the Python of
the venv ``jazzy_env.py`` builds (never with wcdrive's, and it never imports
wcdrive). It sees the bridge only through rclpy: its graph API (node names, topic
names and types, ``get_publishers_info_by_topic`` / ``get_subscriptions_info_by_topic``
with each endpoint's RIHS01 type hash and QoS), subscriptions, publishers and their
QoS events. It prints one JSON object on its last stdout line; the tests assert on it.

Modes (``--mode``):

- ``main``: waits for node ``/wcdrive``; reads the topic table as the graph shows it,
  with the type hashes the venv's own message packages give (``share/<pkg>/msg/*.json``,
  stock Jazzy); subscribes to the data topics with the QoS a stock Jazzy node uses
  (registering incompatible-QoS events everywhere); drives with a BEST_EFFORT and then a
  RELIABLE TwistStamped writer, each on its own; latches ``/estop`` while driving and
  releases it with ``/estop_reset``; and at the end sends SIGTERM to the bridge
  (``--bridge-pid``) and times how long its node and endpoints take to leave the graph
  and the matches to drop.
- ``discover``: a node that joins late (the test starts it long after the bridge) in
  whatever discovery range its environment gives (``ROS_AUTOMATIC_DISCOVERY_RANGE``,
  ``ROS_STATIC_PEERS``, ``ROS_LOCALHOST_ONLY``): how long until it lists ``/wcdrive``
  and until the first ``/odom`` arrives.

- ``replica`` (``check_stack_replica``): a bridge configured as a
  ``diff_drive_controller`` named after the chair (``--controller``: its node and
  ``/<controller>/odom``, ``/<controller>/cmd_vel``), with its TF left to the stack,
  and its ``/scan`` as the stack's lidar driver would publish it.

    ROS_DOMAIN_ID=150 RMW_IMPLEMENTATION=rmw_fastrtps_cpp venv/bin/python jazzy_client.py \\
        --mode main --bridge-pid 1234
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu, JointState, LaserScan
from std_msgs.msg import Bool, Empty
from tf2_msgs.msg import TFMessage

BRIDGE = "/wcdrive"
#: The QoS a stock Jazzy node subscribes with: rclcpp/rclpy's default (reliable,
#: volatile, keep last 10) for odometry, joints and diagnostics; SensorDataQoS for the
#: IMU and the scan; tf2_ros' listeners for /tf (keep last 100) and /tf_static
#: (transient local, keep last 100).
DEFAULT = QoSProfile(depth=10)
TF_QOS = QoSProfile(depth=100)
TF_STATIC_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SUBSCRIBE = {
    "/odom": (Odometry, DEFAULT), "/joint_states": (JointState, DEFAULT),
    "/diagnostics": (DiagnosticArray, DEFAULT), "/imu": (Imu, qos_profile_sensor_data),
    "/scan": (LaserScan, qos_profile_sensor_data), "/tf": (TFMessage, TF_QOS),
    "/tf_static": (TFMessage, TF_STATIC_QOS),
}
BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def log(text: str) -> None:
    print(f"jazzy_client: {text}", file=sys.stderr, flush=True)


def stock_hash(msgtype: str) -> str | None:
    """The RIHS01 hash of ``pkg/msg/Msg`` as the venv's stock package records it."""
    package, _, name = msgtype.split("/")
    for prefix in {sys.prefix, *os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)}:
        path = Path(prefix) / "share" / package / "msg" / f"{name}.json"
        if prefix and path.exists():
            for entry in json.loads(path.read_text())["type_hashes"]:
                if entry["type_name"] == msgtype:
                    return str(entry["hash_string"])
    return None


def qos_dict(qos: QoSProfile) -> dict[str, Any]:
    return {"reliability": qos.reliability.name.lower(), "durability": qos.durability.name.lower(),
            "history": qos.history.name.lower(), "depth": qos.depth}


class Client:
    """The rclpy node and what it saw."""

    def __init__(self, name: str) -> None:
        self.node = Node(name)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.incompatible: list[dict[str, Any]] = []
        self.received: dict[str, list[tuple[float, Any]]] = {}

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.02, max(0.0, end - time.monotonic())))

    def spin_until(self, condition: Any, timeout: float) -> float | None:
        """Spins until ``condition()``; the seconds it took, or None at ``timeout``."""
        start = time.monotonic()
        while not condition():
            if time.monotonic() - start > timeout:
                return None
            self.executor.spin_once(timeout_sec=0.01)
        return time.monotonic() - start

    def _incompatible(self, topic: str, side: str) -> Any:
        def note(info: Any) -> None:
            policy = getattr(info, "last_policy_kind", None)
            self.incompatible.append({"topic": topic, "side": side, "total": info.total_count,
                                      "policy": getattr(policy, "name", str(policy))})
            log(f"incompatible QoS on {topic} ({side}): {policy}")
        return note

    def subscribe(self, topic: str, msgtype: Any, qos: QoSProfile) -> Any:
        self.received[topic] = []

        def keep(message: Any) -> None:
            self.received[topic].append((time.monotonic(), message))
            del self.received[topic][:-2000]
        events = SubscriptionEventCallbacks(incompatible_qos=self._incompatible(topic, "subscription"))
        return self.node.create_subscription(msgtype, topic, keep, qos, event_callbacks=events)

    def publisher(self, topic: str, msgtype: Any, qos: QoSProfile) -> Any:
        events = PublisherEventCallbacks(incompatible_qos=self._incompatible(topic, "publisher"))
        return self.node.create_publisher(msgtype, topic, qos, event_callbacks=events)

    # ---- the graph -------------------------------------------------------------------
    def node_listed(self, full_name: str = BRIDGE) -> bool:
        names = {(ns.rstrip("/") + "/" + n) for n, ns in self.node.get_node_names_and_namespaces()}
        return full_name in names

    def endpoints(self, topic: str, node_name: str = "wcdrive") -> list[dict[str, Any]]:
        """The bridge's endpoints on ``topic``, as the graph shows them."""
        seen = []
        for kind, infos in (("pub", self.node.get_publishers_info_by_topic(topic)),
                            ("sub", self.node.get_subscriptions_info_by_topic(topic))):
            for info in infos:
                if info.node_name != node_name:
                    continue
                seen.append({"dir": kind, "type": info.topic_type, "hash": str(info.topic_type_hash),
                             "stock_hash": stock_hash(info.topic_type), **qos_dict(info.qos_profile)})
        return seen

    def topic_table(self, node_name: str = "wcdrive") -> dict[str, list[dict[str, Any]]]:
        table = {}
        for topic, _types in self.node.get_topic_names_and_types():
            rows = self.endpoints(topic, node_name)
            if rows:
                table[topic] = rows
        return table

    # ---- data ------------------------------------------------------------------------
    def odom_x(self) -> float | None:
        odom = self.received.get("/odom")
        return odom[-1][1].pose.pose.position.x if odom else None

    def odom_speed(self) -> float:
        odom = self.received.get("/odom")
        return abs(odom[-1][1].twist.twist.linear.x) if odom else math.nan

    def drive(self, publisher: Any, linear: float, seconds: float, rate: float = 20.0) -> None:
        """Publishes TwistStamped ``linear`` m/s at ``rate`` Hz for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            message = TwistStamped()
            message.header.stamp = self.node.get_clock().now().to_msg()
            message.twist.linear.x = linear
            publisher.publish(message)
            self.spin(1.0 / rate)


def summary_of_data(client: Client, since: float) -> dict[str, Any]:
    """Per topic: how many arrived after ``since`` (all of them for ``/tf_static``, sent
    once), their rate by arrival and by header stamp (Hz), and what the last one says."""
    out: dict[str, Any] = {}
    for topic, everything in client.received.items():
        samples = everything if topic == "/tf_static" else [s for s in everything if s[0] >= since]
        entry: dict[str, Any] = {"count": len(samples)}
        if len(samples) >= 2:
            span = samples[-1][0] - samples[0][0]
            entry["rate_hz"] = round((len(samples) - 1) / span, 1) if span > 0 else None
            if hasattr(samples[0][1], "header"):
                first, last = (m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
                               for m in (samples[0][1], samples[-1][1]))
                entry["stamp_rate_hz"] = (round((len(samples) - 1) / (last - first), 1) if last > first
                                          else None)
        if samples:
            last = samples[-1][1]
            if hasattr(last, "header"):
                entry["frame_id"] = last.header.frame_id
            if topic == "/scan":
                entry["beams"] = len(last.ranges)
                entry["range_min"] = last.range_min
            if topic in ("/tf", "/tf_static"):
                entry["frames"] = sorted({(t.header.frame_id, t.child_frame_id)
                                          for _, m in samples for t in m.transforms})
        out[topic] = entry
    return out


def leave_graph(client: Client, bridge_pid: int, odom_sub: Any, cmd_pub: Any) -> dict[str, Any]:
    """Sends SIGTERM to the bridge and times (s) how long each trace of it stays."""
    checks = {
        "node": lambda: not client.node_listed(),
        "odom_publisher": lambda: client.node.count_publishers("/odom") == 0,
        "cmd_vel_subscriber": lambda: client.node.count_subscribers("/cmd_vel") == 0,
        "odom_matched": lambda: odom_sub.get_publisher_count() == 0,
        "cmd_vel_matched": lambda: cmd_pub.get_subscription_count() == 0,
    }
    gone: dict[str, float | None] = dict.fromkeys(checks)
    os.kill(bridge_pid, signal.SIGTERM)
    start = time.monotonic()
    while time.monotonic() - start < 15.0 and any(v is None for v in gone.values()):
        for name, check in checks.items():
            if gone[name] is None and check():
                gone[name] = round(time.monotonic() - start, 3)
        client.executor.spin_once(timeout_sec=0.005)
    left = [v for v in gone.values()]
    return {"after_sigterm_s": gone,
            "all_gone_s": None if any(v is None for v in left) else max(v for v in left if v is not None)}


def run_main(args: argparse.Namespace) -> dict[str, Any]:
    client = Client("jazzy_probe")
    result: dict[str, Any] = {"rmw": rclpy.utilities.get_rmw_implementation_identifier()}
    result["discovered_s"] = client.spin_until(client.node_listed, 30.0)
    if result["discovered_s"] is None:
        return result
    expected = args.topics.split(",")
    result["topics_s"] = client.spin_until(
        lambda: expected_seen(client, expected), 15.0)
    subs = {topic: client.subscribe(topic, *spec) for topic, spec in SUBSCRIBE.items()}
    estop = client.publisher("/estop", Bool, DEFAULT)
    reset = client.publisher("/estop_reset", Empty, DEFAULT)
    first = ("/odom", "/imu", "/tf", "/tf_static", "/scan")
    client.spin_until(lambda: all(client.received[t] for t in first), 15.0)
    since = time.monotonic()
    client.spin(3.0)
    result["data"] = summary_of_data(client, since)
    result["table"] = client.topic_table()
    result["node_names"] = sorted(ns.rstrip("/") + "/" + n
                                  for n, ns in client.node.get_node_names_and_namespaces())

    # Drive: a BEST_EFFORT writer (Jazzy's controller stack), then a RELIABLE one.
    drives = {}
    for label, qos in (("best_effort", BEST_EFFORT), ("reliable", RELIABLE)):
        pub = client.publisher("/cmd_vel", TwistStamped, qos)
        matched = client.spin_until(lambda pub=pub: pub.get_subscription_count() > 0, 5.0)
        x0 = client.odom_x()
        client.drive(pub, 0.3, 2.0)
        moving = client.odom_speed()
        x1 = client.odom_x()
        client.drive(pub, 0.0, 1.0)
        drives[label] = {"matched_s": matched, "speed": round(moving, 3),
                         "moved_m": None if x0 is None or x1 is None else round(x1 - x0, 3)}
        if label == "best_effort":
            client.node.destroy_publisher(pub)
        else:
            cmd = pub
    result["drive"] = drives

    # The e-stop: latched while a 0.3 m/s stream goes on, then released.
    client.drive(cmd, 0.3, 1.5)
    before = client.odom_speed()
    estop.publish(Bool(data=True))
    client.drive(cmd, 0.3, 2.0)
    x0 = client.odom_x()
    client.drive(cmd, 0.3, 1.0)
    x1 = client.odom_x()
    held = {"speed_before": round(before, 3), "speed_held": round(client.odom_speed(), 3),
            "moved_held_m": None if x0 is None or x1 is None else round(x1 - x0, 4)}
    reset.publish(Empty())
    client.drive(cmd, 0.3, 2.0)
    held["speed_after_reset"] = round(client.odom_speed(), 3)
    client.drive(cmd, 0.0, 1.0)
    result["estop"] = held
    result["incompatible_qos"] = list(client.incompatible)

    if args.bridge_pid:
        result["leave"] = leave_graph(client, args.bridge_pid, subs["/odom"], cmd)
    client.node.destroy_node()
    return result


def expected_seen(client: Client, expected: list[str]) -> bool:
    names = {name for name, _ in client.node.get_topic_names_and_types()}
    return all(t in names for t in expected)


def run_discover(args: argparse.Namespace) -> dict[str, Any]:
    client = Client(args.name)
    settings = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY")
    env = {k: os.environ[k] for k in settings if k in os.environ}
    client.subscribe("/odom", Odometry, DEFAULT)
    found = client.spin_until(client.node_listed, args.timeout)
    odom = None if found is None else client.spin_until(lambda: bool(client.received["/odom"]), args.timeout)
    result = {"env": env, "node_s": found, "odom_s": None if odom is None else round((found or 0) + odom, 3),
              "incompatible_qos": client.incompatible}
    client.node.destroy_node()
    return result


def scan_summary(scan: Any) -> dict[str, Any]:
    """What a scan filter relies on: the angle span, beam count, ``range_min``, frame,
    the intensities seen, and every return as (stated angle, range)."""
    returns = [[round(scan.angle_min + i * scan.angle_increment, 6), round(r, 4)]
               for i, r in enumerate(scan.ranges) if math.isfinite(r)]
    return {"frame_id": scan.header.frame_id, "angle_min": scan.angle_min, "angle_max": scan.angle_max,
            "beams": len(scan.ranges), "range_min": scan.range_min,
            "intensities": sorted({round(v, 3) for v in scan.intensities}), "returns": returns}


def check_stack_replica(client: Client, controller: str, seconds: float = 2.0) -> dict[str, Any]:
    """A later check of a bridge under an existing stack: the node named after the
    ``diff_drive_controller`` (``/<controller>``), odometry on ``/<controller>/odom``
    read as an EKF reads it, ``/scan`` read as a scan filter reads it (sensor data QoS;
    a scan taken standing: ``scan_summary``), a BEST_EFFORT TwistStamped writer on
    ``/<controller>/cmd_vel`` that moves it; what the graph and the data showed."""
    odom_topic, cmd_topic = f"/{controller}/odom", f"/{controller}/cmd_vel"
    out: dict[str, Any] = {
        "node_listed": client.spin_until(lambda: client.node_listed(f"/{controller}"), 20.0)}
    client.subscribe(odom_topic, Odometry, DEFAULT)
    pub = client.publisher(cmd_topic, TwistStamped, BEST_EFFORT)
    out["matched_s"] = client.spin_until(lambda: pub.get_subscription_count() > 0, 5.0)
    out["endpoints"] = {t: client.endpoints(t, controller) for t in (odom_topic, cmd_topic)}
    client.subscribe("/scan", LaserScan, qos_profile_sensor_data)   # as a scan filter reads it
    samples, scans = client.received[odom_topic], client.received["/scan"]
    client.spin_until(lambda: bool(samples) and bool(scans), 5.0)
    out["scan"] = scan_summary(scans[-1][1]) if scans else None        # taken standing
    x0 = samples[-1][1].pose.pose.position.x if samples else None
    client.drive(pub, 0.3, seconds)
    x1 = samples[-1][1].pose.pose.position.x if samples else None
    out["moved_m"] = None if x0 is None or x1 is None else round(x1 - x0, 3)
    out["top_speed_mps"] = round(max((abs(m.twist.twist.linear.x) for _, m in samples), default=0.0), 3)
    # the stack's EKF owns odom -> base_link and its robot_state_publisher the static
    # frames: the bridge publishes neither, so no frame gets a second parent
    out["tf_publishers"] = {t: [i.node_name for i in client.node.get_publishers_info_by_topic(t)]
                            for t in ("/tf", "/tf_static")}
    out["incompatible_qos"] = list(client.incompatible)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=("main", "discover", "replica"), required=True)
    parser.add_argument("--bridge-pid", type=int, default=0, help="main: SIGTERM this at the end")
    parser.add_argument("--topics", default="/odom,/tf,/tf_static,/joint_states,/imu,/scan,/diagnostics,"
                                            "/cmd_vel,/estop,/estop_reset")
    parser.add_argument("--name", default="jazzy_late_joiner", help="discover: the node's name")
    parser.add_argument("--timeout", type=float, default=20.0, help="discover: give up after (s)")
    parser.add_argument("--controller", default="wheelchair_controller",
                        help="replica: the diff_drive_controller's name the bridge's node takes")
    args = parser.parse_args()
    rclpy.init()
    try:
        if args.mode == "replica":
            result = check_stack_replica(Client("jazzy_replica"), args.controller, seconds=4.0)
        else:
            result = run_main(args) if args.mode == "main" else run_discover(args)
    finally:
        rclpy.try_shutdown()
    print(json.dumps(result, default=str), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
