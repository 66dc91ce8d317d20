"""ROS 2's QoS profiles as DDS QoS, and the USER_DATA a ROS 2 Jazzy endpoint carries.

A ``Profile`` is what ``rclcpp`` names a QoS: reliability, durability, history depth
(``wcdrive.ros2.topics``, the one topic table, defines them). The profiles are
rclcpp's: ``DEFAULT`` (reliable, volatile, keep last 10: ``/odom``,
``/joint_states``, ``/diagnostics``, ``/estop``, ``/estop_reset``), ``COMMAND`` (best
effort, volatile, keep last 10: the ``/cmd_vel`` reader, which so matches best-effort
and reliable writers alike), ``SENSOR_DATA`` (best effort,
volatile, keep last 5: ``/imu``, ``/scan``), ``CLOCK`` (best effort, keep last 1),
``TF`` (tf2_ros' dynamic broadcaster: reliable, volatile, keep last 100), ``TF_STATIC``
(reliable, transient local, keep last 1: a late subscriber still gets the static
transforms) and ``DISCOVERY`` (``ros_discovery_info``: reliable, transient local,
keep last 1, as ``rmw_dds_common`` publishes it).

``qos(profile, type_hash)`` adds what every ROS 2 Jazzy RMW sets on an endpoint:
the type hash in USER_DATA (``typehash=RIHS01_<64 hex>;``) and the plain CDR
(XCDR1) data representation.
"""

from __future__ import annotations

from cyclonedds.core import Policy, Qos

from wcdrive.ros2.topics import CLOCK, COMMAND, DEFAULT, DISCOVERY, SENSOR_DATA, TF, TF_STATIC, Profile

__all__ = ["CLOCK", "COMMAND", "DEFAULT", "DISCOVERY", "SENSOR_DATA", "TF", "TF_STATIC", "Profile", "qos",
           "user_data"]


def user_data(type_hash: str) -> bytes:
    """The USER_DATA of a ROS 2 Jazzy endpoint of a type with RIHS01 ``type_hash``."""
    return f"typehash={type_hash};".encode()


def qos(profile: Profile, type_hash: str) -> Qos:
    """The DDS QoS of an endpoint with ``profile`` for a type with hash ``type_hash``."""
    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=100_000_000) if profile.reliable
        else Policy.Reliability.BestEffort,
        Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
        Policy.History.KeepLast(profile.depth),
        Policy.DataRepresentation(use_cdrv0_representation=True),
        Policy.Userdata(user_data(type_hash)),
    )
