"""What Slamtec's two ROS 2 drivers publish of a turn: ``sllidar_ros2`` and the older
``rplidar_ros`` (its ros2 branch), with their ``inverted`` and ``angle_compensate``
parameters.

    driver = LidarDriver("rplidar_ros", angle_compensate=True)
    fields = driver.publish(ranges, intensities, times, (0.0, driver.compensated_span_deg),
                            scan_time=0.1, inverted=True)     # nodes in the device's order

Both drivers' ``publish_scan`` take the turn's nodes in the device's order (rising
device angle, clockwise from the device's front seen from its top), and the two angles
that bound them (``angle_min``, ``angle_max``: radians, as floats). Read from the
source: ``src/sllidar_node.cpp`` of Slamtec/sllidar_ros2 (main, 3430009; "sl" below)
and ``src/rplidar_node.cpp`` of Slamtec/rplidar_ros (branch ros2, 1597018; "rp"):

- ``reversed = angle_max > angle_min``; then the message's ``angle_min = M_PI -
  angle_max`` and ``angle_max = M_PI - angle_min`` (else ``M_PI - angle_min`` and ``M_PI
  - angle_max``), ``angle_increment = (angle_max - angle_min) / (node_count - 1)`` of
  the message's float fields, ``time_increment = scan_time / (node_count - 1)`` (sl
  216-227, rp 245-256): the device's angle ``a`` is the laser frame's ``pi - a``.
- ``reverse_data = (!inverted && reversed) || (inverted && !reversed)`` (sl 233, rp
  262): the nodes are published last first unless ``inverted`` is set. A head-down
  device sweeps the other way round, so its driver, told, keeps the nodes in the
  device's order.
- ``range_min``: 0.05 in sllidar_ros2 (sl 228, commit "set the minimum distance to
  5cm"), 0.15 in rplidar_ros (rp 257); ``range_max`` the scan mode's ``max_distance``;
  a node's range is ``dist_mm_q2 / 4.0f / 1000``, ``+inf`` for 0.
- Intensities: ``quality >> 2`` (the S3's dense capsules give a return quality ``0x2F
  << 2``, ``sdk/src/dataunpacker/unpacker/handler_capsules.cpp`` 778, the dense capsule: 47,
  ``LidarModel.intensity``). sllidar_ros2 writes node ``i``'s at the index its range
  goes to (sl 234-252); rplidar_ros writes ``intensities[apply_index] =
  nodes[apply_index].quality >> 2`` (rp 282): the node at the *published* index, so
  when the ranges are reversed its intensities are not (they stay in the device's
  order).
- ``angle_compensate`` (the S3 launch files' default): the nodes are binned into
  ``360 * multiple`` slots (``wcdrive.plant.lidar``'s docstring; sl 372-397, rp
  483-508) and published with ``angle_min = DEG2RAD(0.0f)`` and ``angle_max =
  DEG2RAD(360.0f)`` in sllidar_ros2 (sl 369-370), but ``DEG2RAD(359.0f)`` in rplidar_ros
  (rp 480-481): its scan claims a span of pi - 359 deg .. pi over the same 360 degrees
  of slots, so its beam ``i``'s stated angle is off the slot's by up to 1 degree (0 at
  the end published last).
- Without it: the nodes from the first with a return to the last with one, in the
  device's order (``ascendScanData`` sorted them by angle, ``sdk/src/sl_lidar_driver.cpp``
  129-183), bounded by those two nodes' angles (``DEG2RAD(getAngle(node))``; sl
  403-419, rp 514-530): the beam count changes from turn to turn. A turn without a
  single return (``ascendScanData`` fails) is published whole, bounded by
  ``DEG2RAD(0.0f)`` and ``DEG2RAD(359.0f)`` (sl 421-428, rp 532-539). Told
  ``inverted``, the drivers keep the nodes in the device's order but still state them
  from ``pi - last`` to ``pi - first``: every stated angle is off by ``360 deg - (first
  + last)``, that is ``angle_min + angle_max`` (nothing for a turn with returns all
  round; tens of degrees for a chair with walls on one side only). The drivers' own
  slip, kept.

Not modelled: rplidar_ros's ``flip_x_axis`` (off by default; rp 264-276), and, with
``angle_compensate``, the whole-turn fallback for a turn without a single return (the
simulated scan then has the usual slots, every one ``+inf``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: The drivers modelled, and the ``range_min`` each publishes (m).
RANGE_MIN = {"sllidar_ros2": 0.05, "rplidar_ros": 0.15}
DRIVERS = tuple(RANGE_MIN)
_f32 = np.float32


def _deg2rad(degrees: float) -> float:
    """The drivers' ``DEG2RAD`` of a float, stored into a ``float`` variable."""
    return float(_f32(float(_f32(degrees)) * math.pi / 180.0))


@dataclass(frozen=True)
class ScanFields:
    """The fields of one published scan that depend on the driver (float32 figures)."""

    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    range_min: float
    ranges: np.ndarray
    intensities: np.ndarray
    beam_time: np.ndarray


@dataclass(frozen=True)
class LidarDriver:
    """A Slamtec ROS 2 driver (``DRIVERS``) and its ``angle_compensate`` parameter (its
    ``inverted`` one is ``LidarMount.driver_inverted``: with the mount it fixes the laser
    frame). A ``ValueError`` names an unknown driver."""

    name: str = "sllidar_ros2"
    angle_compensate: bool = True

    def __post_init__(self) -> None:
        if self.name not in RANGE_MIN:
            raise ValueError(f"lidar driver {self.name!r}: must be one of {', '.join(DRIVERS)}")

    @property
    def range_min(self) -> float:
        """The ``range_min`` it publishes (m)."""
        return RANGE_MIN[self.name]

    @property
    def compensated_span_deg(self) -> float:
        """The ``angle_max`` (degrees) it hands ``publish_scan`` for binned nodes: 360 in
        sllidar_ros2, 359 in rplidar_ros."""
        return 360.0 if self.name == "sllidar_ros2" else 359.0

    def publish(self, nodes_ranges: np.ndarray, nodes_intensities: np.ndarray, nodes_time: np.ndarray,
                bounds_deg: tuple[float, float], scan_time: float, inverted: bool) -> ScanFields:
        """``publish_scan`` of nodes in the device's order (ranges float32 m, ``inf``
        for none; their intensities and times), bounded by the device angles
        ``bounds_deg`` (the first node's and the last's, as floats)."""
        count = len(nodes_ranges)
        lo, hi = _deg2rad(bounds_deg[0]), _deg2rad(bounds_deg[1])
        reversed_ = hi > lo
        first, last = (math.pi - hi, math.pi - lo) if reversed_ else (math.pi - lo, math.pi - hi)
        angle_min, angle_max = float(_f32(first)), float(_f32(last))
        with np.errstate(divide="ignore", invalid="ignore"):
            increment = float(_f32(np.float64(float(_f32(angle_max - angle_min))) / np.float64(count - 1)))
            time_increment = float(_f32(np.float64(scan_time) / np.float64(count - 1)))
        reverse = reversed_ != inverted
        ranges = nodes_ranges[::-1] if reverse else nodes_ranges
        times = nodes_time[::-1] if reverse else nodes_time
        follows = self.name == "sllidar_ros2"        # rplidar_ros: the node at the published index
        intensities = nodes_intensities[::-1] if reverse and follows else nodes_intensities
        return ScanFields(angle_min, angle_max, increment, time_increment, float(_f32(self.range_min)),
                          np.ascontiguousarray(ranges, dtype=np.float32),
                          np.ascontiguousarray(intensities, dtype=np.float32), np.ascontiguousarray(times))

    def publish_raw(self, ranges: np.ndarray, intensities: np.ndarray, times: np.ndarray,
                    angle_deg: np.ndarray, scan_time: float, inverted: bool) -> ScanFields:
        """Without ``angle_compensate``: the turn's samples in the device's order
        (``angle_deg`` each; ``inf`` for no return) from the first with a return to the
        last, or all of them bounded by 0 and 359 degrees when none has one."""
        hit = np.flatnonzero(np.isfinite(ranges))
        if hit.size == 0:
            return self.publish(ranges, intensities, times, (0.0, 359.0), scan_time, inverted)
        a, b = int(hit[0]), int(hit[-1]) + 1
        bounds = (float(_f32(angle_deg[a])), float(_f32(angle_deg[b - 1])))
        return self.publish(ranges[a:b], intensities[a:b], times[a:b], bounds, scan_time, inverted)


#: The default: sllidar_ros2 with ``angle_compensate``, as its S3 launch file runs it.
SLLIDAR_ROS2 = LidarDriver()
