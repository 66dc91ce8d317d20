"""The one ROS 2 topic table: every topic wcdrive publishes, records or reads, with its
type, QoS profile and frame. The MCAP writer (``wcdrive.ros2.bridge``: ``TOPICS``,
``QOS``), the Foxglove live view (its channels) and the DDS node
(``wcdrive.ros2.dds.node.TOPICS``) are all read from it, so a recording replays with
the QoS the live node offers (``ros2 bag play`` offers each topic as rosbag2 recorded
it) and ``tests/ros2/test_topic_table.py`` checks that the three agree.

The profiles are rclcpp's: ``DEFAULT`` (reliable, volatile, keep last 10),
``SENSOR_DATA`` (best effort, volatile, keep last 5: ``/imu``, ``/scan``, as
``rclcpp::SensorDataQoS``), ``CLOCK`` (best effort, keep last 1), ``TF`` (tf2_ros'
dynamic broadcaster: reliable, volatile, keep last 100), ``TF_STATIC`` (reliable,
transient local, keep last 1: tf2's static broadcaster and map_server, so a late
subscriber still gets the static transforms and the map), ``DISCOVERY``
(``ros_discovery_info``) and ``COMMAND`` (best effort, volatile, keep last 10).

A row's ``profile`` is what its publisher offers, and so what a recording offers it
with; the DDS node reads a topic with the row's ``reader`` profile where it has one
(``Topic.live``). ``/cmd_vel`` is offered as rclcpp's publishers offer it (``DEFAULT``,
reliable: a recording played back then matches best-effort and reliable readers
alike) and read ``COMMAND``, best effort: a best-effort reader matches a best-effort
writer, as Jazzy's ``diff_drive_controller`` stacks publish their commands, and a
reliable one, as ``ros2 topic pub`` and rclcpp's default do; a reliable reader would
match only the second. ``/estop`` and ``/estop_reset`` are read reliably: a latched
e-stop sample is sent again until the bridge has it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["CLOCK", "COMMAND", "DEFAULT", "DISCOVERY", "SENSOR_DATA", "TABLE", "TF", "TF_STATIC",
           "Profile", "Topic", "by_name"]


@dataclass(frozen=True)
class Profile:
    """A ROS 2 QoS profile: ``reliable`` or best effort, ``transient_local`` or
    volatile, keep last ``depth``; deadline, lifespan and liveliness as rclcpp leaves
    them (infinite, automatic)."""

    name: str
    reliable: bool
    transient_local: bool
    depth: int

    def describe(self) -> str:
        """As docs/ros2.md's topic table shows it."""
        return (f"{'reliable' if self.reliable else 'best effort'}, "
                f"{'transient local' if self.transient_local else 'volatile'}, keep last {self.depth}")

    def rosbag2(self) -> dict[str, Any]:
        """The profile as rosbag2 (Jazzy, bag version 9) writes it in
        ``offered_qos_profiles``."""
        infinite = {"sec": 9223372036, "nsec": 854775807}
        return {"history": "keep_last", "depth": self.depth,
                "reliability": "reliable" if self.reliable else "best_effort",
                "durability": "transient_local" if self.transient_local else "volatile",
                "deadline": dict(infinite), "lifespan": dict(infinite), "liveliness": "automatic",
                "liveliness_lease_duration": dict(infinite), "avoid_ros_namespace_conventions": False}


DEFAULT = Profile("default", reliable=True, transient_local=False, depth=10)
SENSOR_DATA = Profile("sensor data", reliable=False, transient_local=False, depth=5)
CLOCK = Profile("clock", reliable=False, transient_local=False, depth=1)
TF = Profile("tf", reliable=True, transient_local=False, depth=100)
TF_STATIC = Profile("tf_static", reliable=True, transient_local=True, depth=1)
DISCOVERY = Profile("ros_discovery_info", reliable=True, transient_local=True, depth=1)
COMMAND = Profile("command", reliable=False, transient_local=False, depth=10)

ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
JOINTS = "sensor_msgs/msg/JointState"
IMU = "sensor_msgs/msg/Imu"
SCAN = "sensor_msgs/msg/LaserScan"
MAP = "nav_msgs/msg/OccupancyGrid"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
CLOCK_MESSAGE = "rosgraph_msgs/msg/Clock"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
BOOL = "std_msgs/msg/Bool"
EMPTY = "std_msgs/msg/Empty"


@dataclass(frozen=True)
class Topic:
    """One row: the ROS ``name``, ``msgtype``, QoS ``profile`` (its publisher's), the
    header's ``frame`` (None: the message has no header, or an empty frame), the DDS
    node's ``direction`` ("pub", "sub", or None: not on the live node), whether an MCAP
    recording or the Foxglove view carries it (``recorded``), ``rate`` (for
    docs/ros2.md) and the DDS node's ``reader`` profile when it reads the topic with
    another than ``profile``."""

    name: str
    msgtype: str
    profile: Profile
    frame: str | None
    direction: str | None
    recorded: bool
    rate: str
    reader: Profile | None = None

    @property
    def live(self) -> Profile:
        """The QoS of the DDS node's endpoint: ``reader`` for a subscription that has
        one, else ``profile``."""
        return self.reader if self.direction == "sub" and self.reader is not None else self.profile


#: Every topic (docs/ros2.md's table is the DDS node's rows).
TABLE: tuple[Topic, ...] = (
    Topic("/odom", ODOMETRY, DEFAULT, "odom", "pub", True, "every telemetry tick (20 Hz chair, 25 Hz Eddie)"),
    Topic("/tf", TF_MESSAGE, TF, None, "pub", True, "with /odom (unless --no-tf)"),
    Topic("/tf_static", TF_MESSAGE, TF_STATIC, None, "pub", True, "once"),
    Topic("/joint_states", JOINTS, DEFAULT, "base_link", "pub", True, "with /odom"),
    Topic("/imu", IMU, SENSOR_DATA, "imu_link", "pub", True, "each gyro sample (400 Hz, sim:// and simavr://)"),
    Topic("/scan", SCAN, SENSOR_DATA, "laser", "pub", True,
          "each turn of the lidar (10 Hz, sim:// and simavr:// with lidar=)"),
    Topic("/diagnostics", DIAGNOSTICS, DEFAULT, None, "pub", False, "1 Hz"),
    Topic("/clock", CLOCK_MESSAGE, CLOCK, None, "pub", False, "with /odom, only with --sim-time"),
    Topic("/cmd_vel", TWIST_STAMPED, DEFAULT, None, "sub", True, "the publisher's (>= 2 Hz to keep moving)",
          reader=COMMAND),
    Topic("/estop", BOOL, DEFAULT, None, "sub", False, "on demand"),
    Topic("/estop_reset", EMPTY, DEFAULT, None, "sub", False, "on demand"),
    Topic("/map", MAP, TF_STATIC, "map", None, True, "once, at the start of a run among walls"),
    Topic("/ground_truth", ODOMETRY, DEFAULT, "odom", None, True, "with /odom (a simulated board)"),
    Topic("/diagnostics/serial", DIAGNOSTICS, DEFAULT, None, None, True, "each line the board sends"),
    Topic("/odometry/filtered", ODOMETRY, DEFAULT, "odom", None, True,
          "with /odom (the EKF, when there is one)"),
)


def by_name(name: str) -> Topic:
    """The row of topic ``name`` (KeyError naming it when there is none)."""
    for topic in TABLE:
        if topic.name == name:
            return topic
    raise KeyError(f"{name!r} is not in wcdrive.ros2.topics.TABLE")
