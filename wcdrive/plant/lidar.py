"""A 2D lidar on the chair, the Slamtec RPLidar S3 by default, and the
``sensor_msgs/LaserScan`` its ROS 2 driver (``sllidar_ros2``) publishes.

    lidar = Lidar(RPLIDAR_S3, LidarMount(x=0.30, z=0.45))
    scan = lidar.scan(world, pose_at, t0=12.3, rng=np.random.default_rng(0))
    scan.ranges          # float32, len(scan.ranges) == lidar.beams, inf for no return

How a scan is made, as the device and the driver make it:

- The head turns at ``scan_hz``; the device takes a sample every ``1 / sample_hz`` s,
  sample ``j`` at device angle ``j * 360 / samples`` degrees, clockwise from its
  front seen from its top, at time ``t0 + j / sample_hz``: each beam is cast from where
  the chair is at that instant (``pose_at``), so a moving chair's scan is distorted as
  the real one is.
- A sample's range is the distance to the world (``World.cast``) plus Gaussian noise
  (``range_sigma``), in the device's quarter millimetres (``dist_mm_q2``); a range
  below ``device_min`` or above ``range_max`` is no return (0).
- The driver (``angle_compensate``, the S3 launch file's default) bins the samples into
  ``360 * multiple`` beams, ``multiple = int(points_per_revolution / 360 + 1)`` (3,240
  for the S3 at 32 kHz and 10 Hz): each sample with a return fills the ``multiple``
  bins from ``int(angle * multiple)`` on, later samples over earlier ones; a bin no
  sample filled is 0. It then publishes ``angle_min = -pi``, ``angle_max = pi``,
  ``angle_increment = 2 pi / (beams - 1)``, ``time_increment = scan_time / (beams -
  1)``, ``range_min`` 0.05 m, ``range_max`` the mode's, 0 as ``+inf``, and the bins in
  reverse order unless its ``inverted`` parameter is set (``sllidar_node.cpp``,
  ``publish_scan``). The bin-to-angle rule is the driver's own and is off by up to one
  bin (0.11 deg) at the end of the turn; the simulated scan keeps that, as the real
  one has it.
- Mounting: the device's front points along the mount's ``yaw`` (its 0 deg is the
  laser frame's -x, as ``pi - angle`` says); ``inverted`` (a 180 deg roll, the head
  down) turns it the other way. The laser frame of ``/tf_static`` then has a roll of pi
  when the mount is inverted and the driver is not told (``driver_inverted``), and
  none otherwise (``tf_roll``).

Figures (``RPLIDAR_S3``): 10 Hz, DenseBoost's 32 kHz, 40 m (white target), 0.05 m
(``sllidar_ros2``'s ``range_min``; Slamtec's ``rplidar_ros`` says 0.15), accuracy +-30
mm (the seed's table from Slamtec's datasheet), taken here as 3 sigma: ``range_sigma``
10 mm. The intensity is a constant for a return (the device's reflectivity figure is
not modelled).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wcdrive.plant.world import World

#: (times (K,)) -> (x, y, heading) arrays (K,) of the chair's base in the map frame.
PoseAt = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class LidarModel:
    """What a lidar model is: its turn and sample rates, ranges and noise."""

    name: str
    scan_hz: float
    sample_hz: float
    range_max: float
    range_min: float            # what the driver publishes as range_min
    device_min: float           # below this the device reports no return
    range_sigma: float
    intensity: float = 47.0

    @property
    def samples(self) -> int:
        """Samples in one turn."""
        return int(self.sample_hz / self.scan_hz)

    @property
    def compensate_multiple(self) -> int:
        """The driver's ``angle_compensate_multiple``."""
        return max(1, int(self.samples / 360.0 + 1))

    @property
    def beams(self) -> int:
        """Beams in each published scan (constant)."""
        return 360 * self.compensate_multiple


RPLIDAR_S3 = LidarModel("rplidar_s3", scan_hz=10.0, sample_hz=32_000.0, range_max=40.0,
                        range_min=0.05, device_min=0.05, range_sigma=0.010)
MODELS = {RPLIDAR_S3.name: RPLIDAR_S3}


@dataclass(frozen=True)
class LidarMount:
    """Where the lidar sits on the chair (base frame, metres and degrees), whether it is
    mounted head down, and whether its driver is told so (``inverted`` parameter)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.4
    yaw_deg: float = 0.0
    inverted: bool = False
    driver_inverted: bool = False

    @property
    def tf_roll(self) -> float:
        """The roll of the laser frame in ``/tf_static`` (0 or pi)."""
        return math.pi if self.inverted != self.driver_inverted else 0.0


@dataclass
class LaserScan:
    """The fields of ``sensor_msgs/LaserScan`` a driver fills (``stamp`` in simulated s)."""

    stamp: float
    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: np.ndarray
    intensities: np.ndarray
    #: ground truth for tests: each published beam's time and direction in the map
    beam_time: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class Lidar:
    """A lidar model on a mount; ``scan`` makes one revolution's ``LaserScan``."""

    model: LidarModel = RPLIDAR_S3
    mount: LidarMount = field(default_factory=LidarMount)
    frame_id: str = "laser"

    @property
    def beams(self) -> int:
        """Beams a scan holds."""
        return self.model.beams

    def samples(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None
                ) -> tuple[np.ndarray, np.ndarray]:
        """One turn of the device: each sample's time and its ``dist_mm_q2`` (0: no
        return), in the order taken."""
        m, mount = self.model, self.mount
        j = np.arange(m.samples)
        times = t0 + j / m.sample_hz
        device = np.radians(j * 360.0 / m.samples)
        x, y, heading = pose_at(times)
        c, s = np.cos(heading), np.sin(heading)
        ox, oy = x + c * mount.x - s * mount.y, y + s * mount.x + c * mount.y
        turn = device - math.pi if mount.inverted else math.pi - device
        angles = heading + math.radians(mount.yaw_deg) + turn
        ranges = world.cast(np.column_stack((ox, oy)), angles, math.inf)
        if rng is not None and m.range_sigma > 0:
            ranges = ranges + rng.normal(0.0, m.range_sigma, ranges.shape)
        ok = np.isfinite(ranges) & (ranges >= m.device_min) & (ranges <= m.range_max)
        q2 = np.where(ok, np.round(np.where(ok, ranges, 0.0) * 4000.0), 0).astype(np.int64)
        return times, q2

    def scan(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None = None
             ) -> LaserScan:
        """The scan of the turn that starts at ``t0``, as the driver publishes it."""
        m = self.model
        times, q2 = self.samples(world, pose_at, t0, rng)
        beams, multiple = m.beams, m.compensate_multiple
        angle_deg = np.arange(m.samples) * 360.0 / m.samples
        start_bin = np.minimum((angle_deg.astype(np.float32) * multiple).astype(np.int64), beams - 1)
        valid = np.flatnonzero(q2 != 0)
        # bin b holds the last sample with a return whose bins (start .. start + multiple - 1,
        # clamped at the end) reach b
        b = np.arange(beams)
        if valid.size == 0:
            node = np.full(beams, -1)
        else:
            last = np.searchsorted(start_bin[valid], b, side="right") - 1
            node = np.where(last >= 0, valid[np.maximum(last, 0)], -1)
        reaches = (node >= 0) & ((start_bin[np.maximum(node, 0)] + multiple - 1 >= b) | (b == beams - 1))
        bins_q2 = np.where(reaches, q2[np.maximum(node, 0)], 0)
        bins_t = np.where(reaches, times[np.maximum(node, 0)], np.nan)
        if not self.mount.driver_inverted:
            bins_q2, bins_t = bins_q2[::-1], bins_t[::-1]
        ranges = (bins_q2.astype(np.float32) / np.float32(4.0)) / np.float32(1000.0)
        ranges = np.where(bins_q2 == 0, np.float32(np.inf), ranges).astype(np.float32)
        intensities = np.where(bins_q2 == 0, 0.0, m.intensity).astype(np.float32)
        scan_time = 1.0 / m.scan_hz
        # the driver: DEG2RAD(360.0f) and DEG2RAD(0.0f) as floats, M_PI a double, each
        # field a float32
        f32 = np.float32
        angle_min = float(f32(math.pi - float(f32(2 * math.pi))))
        angle_max = float(f32(math.pi))
        increment = float(f32((angle_max - angle_min) / (beams - 1)))
        return LaserScan(t0, self.frame_id, angle_min, angle_max, increment,
                         float(f32(scan_time / (beams - 1))), float(f32(scan_time)), float(f32(m.range_min)),
                         float(f32(m.range_max)), ranges, intensities, bins_t)
