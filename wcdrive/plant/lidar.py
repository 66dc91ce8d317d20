"""A 2D lidar on the chair, the Slamtec RPLidar S3 by default, and the
``sensor_msgs/LaserScan`` its ROS 2 driver publishes (``sllidar_ros2`` by default, or
the older ``rplidar_ros``: ``wcdrive.plant.lidar_driver``).

    lidar = Lidar(RPLIDAR_S3, LidarMount(x=0.30, z=0.45))
    lidar = configured_lidar("rplidar_s3", "-0.30,0,0.25,180,0,180", "rplidar_ros",
                             inverted=True)      # head down, facing back: m and degrees
    scan = lidar.scan(world, pose_at, t0=12.3, rng=np.random.default_rng(0))
    scan.ranges          # float32, len(scan.ranges) == lidar.beams, inf for no return

    plant.start_motion_log()
    start, t0 = plant.pose, plant.time
    ...                                                  # the plant steps through the turn
    track = MotionTrack(start, t0, plant.take_motion_log())
    scan = lidar.scan(world, track, t0, rng)             # the poses integrated in C

    with ScanPipe() as pipe:                             # turns made on a C thread (or ScanPipe.open())
        pending = lidar.start_scan(world, track, t0, rng, pipe)
        ...                                              # the plant steps through the next turn
        scan = pending.result()

``scan`` makes the whole turn in C (``wcdrive.plant.raycast``: the poses, the casts,
the noise from ``rng``'s standard normal draws, the quantisation and the binning, in
one call); ``start_scan`` does the same on a ``ScanPipe``'s thread, the noise drawn
at once (the generator's draws in the order of the calls), while the caller runs on.
``scan_numpy`` is the same turn in numpy, the reference: the same noise draws give
the same quarter millimetres, but where a range lies within rounding of a half
quarter millimetre (the C poses and directions round differently: by 1e-15 of the
figures). Without the C helper ``scan`` and ``start_scan`` are ``scan_numpy``.

How a scan is made, as the device and the driver make it:

- The head turns at ``scan_hz``; the device takes a sample every ``1 / sample_hz`` s,
  sample ``j`` at device angle ``j * 360 / samples`` degrees, clockwise from its
  front seen from its top, at time ``t0 + j / sample_hz``: each beam is cast from where
  the chair is at that instant (``pose_at``), so a moving chair's scan is distorted as
  the real one is.
- A sample's range is the distance to the world (``World.cast``) plus Gaussian noise
  (``range_sigma``), in the device's quarter millimetres (``dist_mm_q2``); a range
  below ``device_min`` or above ``range_max`` is no return (0).
- The driver (``angle_compensate``, the S3 launch files' default) bins the samples into
  ``360 * multiple`` beams, ``multiple = int(points_per_revolution / 360 + 1)`` (3,240
  for the S3 at 32 kHz and 10 Hz): each sample with a return fills the ``multiple``
  bins from ``int(angle * multiple)`` on (the last bin for any past the end), later
  samples over earlier ones; a bin no sample filled is 0. It then publishes
  ``angle_min = -pi``, ``angle_max = pi``, ``angle_increment = 2 pi / (beams - 1)``,
  ``time_increment = scan_time / (beams - 1)``, ``range_min`` 0.05 m, ``range_max``
  the mode's, 0 as ``+inf``, and the bins in reverse order unless its ``inverted``
  parameter is set (``sllidar_node.cpp``, ``publish_scan``). The bin-to-angle rule is
  the driver's own and is off by up to one bin (0.11 deg) at the end of the turn; the
  simulated scan keeps that, as the real one has it. ``rplidar_ros`` publishes the
  same bins with its own angles, ``range_min`` and intensities, and either driver
  without ``angle_compensate`` publishes the samples themselves (``LidarDriver``, whose
  docstring cites the lines of both drivers).
- Mounting (``wcdrive.plant.lidar_mount``): the device's front points along the mount's
  ``yaw`` (its 0 deg is the laser frame's -x, as ``pi - angle`` says); ``inverted`` (a
  180 deg roll, the head down) turns it the other way. The laser frame of
  ``/tf_static`` then has a roll of pi when the mount is inverted and the driver is not
  told (``driver_inverted``), and none otherwise (``tf_roll``; the quaternion:
  ``LidarMount.laser_rotation``).

Figures (``RPLIDAR_S3``): 10 Hz, DenseBoost's 32 kHz, 40 m (white target), 0.05 m
(``sllidar_ros2``'s ``range_min``; Slamtec's ``rplidar_ros`` says 0.15), accuracy +-30
mm (the seed's table from Slamtec's datasheet), taken here as 3 sigma: ``range_sigma``
10 mm. The intensity is a constant for a return (the device's reflectivity figure is
not modelled).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields

import numpy as np

from wcdrive.plant.lidar_driver import SLLIDAR_ROS2, LidarDriver
from wcdrive.plant.lidar_mount import SEED_MOUNT as SEED_MOUNT
from wcdrive.plant.lidar_mount import LidarMount as LidarMount
from wcdrive.plant.lidar_mount import parse_mount
from wcdrive.plant.raycast import ScanJob, ScanPipe, Turn, draws_in_c, integrate_motion
from wcdrive.plant.world import World

#: (times (K,)) -> (x, y, heading) arrays (K,) of the chair's base in the map frame.
PoseAt = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]
Knots = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class MotionTrack:
    """The chair's pose over a stretch of time, a ``PoseAt``: from its pose ``start``
    (x, y, heading) at ``t0`` and the plant's motion log of the steps since
    (``Plant.take_motion_log``: rows of time, forward and lateral speed of the axle
    midpoint, yaw rate, ...), each step turning the heading at its yaw rate and moving
    the chair at its speeds along the heading at the step's middle; linear between the
    steps, held before ``t0`` and after the last. ``offset`` shifts x and y (the map
    frame's origin in the plant's)."""

    def __init__(self, start: tuple[float, float, float], t0: float, log: np.ndarray,
                 offset: tuple[float, float] = (0.0, 0.0)) -> None:
        self.start = (start[0] + offset[0], start[1] + offset[1], start[2])
        self.t0 = t0
        self.log = np.asarray(log, dtype=float).reshape(len(log), -1)

    def knots_numpy(self) -> Knots:
        """The knots (times, x, y, heading; ``len(log) + 1`` each), integrated with
        numpy: the reference."""
        log, (x0, y0, h0) = self.log, self.start
        t = np.concatenate(([self.t0], log[:, 0]))
        dt = np.diff(t)
        turn = log[:, 3] * dt
        heading = h0 + np.concatenate(([0.0], np.cumsum(turn)))
        mid = heading[1:] - turn / 2
        c, s = np.cos(mid), np.sin(mid)
        x = x0 + np.concatenate(([0.0], np.cumsum((log[:, 1] * c - log[:, 2] * s) * dt)))
        y = y0 + np.concatenate(([0.0], np.cumsum((log[:, 1] * s + log[:, 2] * c) * dt)))
        return t, x, y, heading

    @functools.cached_property
    def knots(self) -> Knots:
        """The knots, integrated in C (``knots_numpy`` without the C helper), or those a
        C scan of this track integrated."""
        return integrate_motion(self.start, self.t0, self.log) or self.knots_numpy()

    def _integrated(self, job: ScanJob) -> None:
        """Keeps the knots of a scan job made from this track (the same figures as
        ``integrate_motion``'s, the same C from the same log) as ``knots``."""
        self.__dict__.setdefault("knots", job.knots)

    def __call__(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t, x, y, heading = self.knots
        return np.interp(times, t, x), np.interp(times, t, y), np.interp(times, t, heading)


@dataclass(frozen=True)
class LidarModel:
    """What a lidar model is: its turn and sample rates, ranges and noise."""

    name: str
    scan_hz: float
    sample_hz: float
    range_max: float
    range_min: float            # sllidar_ros2's range_min (a scan carries its driver's)
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


@dataclass(eq=False)
class LaserScan:
    """The fields of ``sensor_msgs/LaserScan`` a driver fills (``stamp`` in simulated s).
    Two scans are equal when every field is (the arrays element by element, a NaN
    beam time or board stamp equal to a NaN)."""

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
    #: ground truth for tests: each published beam's time (NaN: no sample filled it)
    beam_time: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    #: the first beam's time on the board's clock when ``stamp`` is a host time
    #: (``Wheelchair.scan``; NaN otherwise)
    board_stamp: float = math.nan

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LaserScan):
            return NotImplemented
        return all(np.array_equal(a, b, equal_nan=True) if isinstance(a, np.ndarray)
                   else a == b or (isinstance(a, float) and isinstance(b, float) and a != a and b != b)
                   for a, b in ((getattr(self, f.name), getattr(other, f.name)) for f in fields(self)))

    __hash__ = None  # type: ignore[assignment]


class PendingScan:
    """A scan being made (``Lidar.start_scan``); ``result`` waits for it."""

    def __init__(self, done: LaserScan | None, finish: Callable[[], LaserScan] | None = None) -> None:
        self._done, self._finish = done, finish

    def result(self) -> LaserScan:
        """The scan (waiting for its thread to make it)."""
        if self._done is None:
            assert self._finish is not None
            self._done, self._finish = self._finish(), None
        return self._done


@dataclass(frozen=True)
class Lidar:
    """A lidar model on a mount; ``scan`` makes one revolution's ``LaserScan``."""

    model: LidarModel = RPLIDAR_S3
    mount: LidarMount = field(default_factory=LidarMount)
    frame_id: str = "laser"
    driver: LidarDriver = SLLIDAR_ROS2

    @property
    def beams(self) -> int:
        """Beams a scan holds: the driver's slots with ``angle_compensate`` (constant);
        without, the samples of a turn, the most a scan holds (it holds those from the
        first return to the last)."""
        return self.model.beams if self.driver.angle_compensate else self.model.samples

    def times(self, t0: float) -> np.ndarray:
        """Each sample's time in the turn from ``t0``."""
        return t0 + np.arange(self.model.samples) / self.model.sample_hz

    def _device_angles(self) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's device angle (deg) and its direction in the chair's frame (rad)."""
        m, mount = self.model, self.mount
        angle_deg = np.arange(m.samples) * 360.0 / m.samples
        device = np.radians(angle_deg)
        turn = device - math.pi if mount.inverted else math.pi - device
        return angle_deg, mount.yaw + turn

    def _first_bins(self, angle_deg: np.ndarray) -> np.ndarray:
        """The driver's first bin of each sample (without ``angle_compensate``, one bin
        a sample: the samples themselves)."""
        m = self.model
        if not self.driver.angle_compensate:
            return np.arange(len(angle_deg))
        first = (angle_deg.astype(np.float32) * m.compensate_multiple).astype(np.int64)
        return np.minimum(first, m.beams - 1)

    @property
    def _multiple(self) -> int:
        """The bins each sample fills."""
        return self.model.compensate_multiple if self.driver.angle_compensate else 1

    def __getstate__(self) -> dict[str, object]:
        # the C scan's description of the turn holds pointers: a copy makes its own
        return {k: v for k, v in self.__dict__.items() if k != "_turn"}

    @functools.cached_property
    def _turn(self) -> Turn:
        m, mount = self.model, self.mount
        angle_deg, direction = self._device_angles()
        return Turn(m.sample_hz, np.column_stack((np.cos(direction), np.sin(direction))),
                    self._first_bins(angle_deg), self.beams, self._multiple, (mount.x, mount.y),
                    m.range_sigma, m.device_min, m.range_max, m.intensity, self._c_reverses)

    @property
    def _c_reverses(self) -> bool:
        """Whether the C scan publishes its bins last first: with ``angle_compensate`` as
        the driver does (``LidarDriver.publish``: unless told ``inverted``); without,
        never (the driver's scan is cut to the returns first)."""
        return self.driver.angle_compensate and not self.mount.driver_inverted

    def _noise(self, rng: np.random.Generator | None) -> np.ndarray | None:
        """The turn's standard normal draws (one a sample), or None for no noise."""
        if rng is None or self.model.range_sigma <= 0:
            return None
        return rng.standard_normal(self.model.samples)

    def samples(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None
                ) -> tuple[np.ndarray, np.ndarray]:
        """One turn of the device, in numpy: each sample's time and its ``dist_mm_q2``
        (0: no return), in the order taken."""
        m, mount = self.model, self.mount
        times = self.times(t0)
        x, y, heading = pose_at(times)
        c, s = np.cos(heading), np.sin(heading)
        ox, oy = x + c * mount.x - s * mount.y, y + s * mount.x + c * mount.y
        angles = heading + self._device_angles()[1]
        ranges = world.cast(np.column_stack((ox, oy)), angles, math.inf)
        noise = self._noise(rng)
        if noise is not None:
            ranges = ranges + m.range_sigma * noise
        ok = np.isfinite(ranges) & (ranges >= m.device_min) & (ranges <= m.range_max)
        q2 = np.where(ok, np.round(np.where(ok, ranges, 0.0) * 4000.0), 0).astype(np.int64)
        return times, q2

    def _job(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None
             ) -> ScanJob | None:
        """The C scan's job for that turn, or None without the C helper: its noise drawn
        by the job from ``rng`` where the C scan can (``draws_in_c``), else now."""
        grid = world.ray_grid
        if grid is None:
            return None
        draw = rng if rng is not None and self.model.range_sigma > 0 and draws_in_c() else None
        noise = None if draw is not None else self._noise(rng)
        if isinstance(pose_at, MotionTrack):
            return ScanJob(grid, self._turn, t0, noise, motion=(pose_at.start, pose_at.log),
                           motion_t0=pose_at.t0, draw=draw)
        times = self.times(t0)
        return ScanJob(grid, self._turn, t0, noise, knots=(times, *pose_at(times)), draw=draw)

    def scan(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None = None
             ) -> LaserScan:
        """The scan of the turn that starts at ``t0``, as the driver publishes it; in C
        (``scan_numpy`` without the C helper). A ``MotionTrack`` is integrated in C;
        any other ``pose_at`` is asked for each sample's pose."""
        job = self._job(world, pose_at, t0, rng)
        if job is None:
            return self.scan_numpy(world, pose_at, t0, rng)
        job.run()
        return self._made(t0, job, pose_at)

    def start_scan(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None,
                   pipe: ScanPipe | None) -> PendingScan:
        """``scan`` made on ``pipe``'s thread: its poses asked for now, the rest while
        the caller runs on; ``result()`` waits for it. Its noise is drawn from ``rng`` on
        that thread where the C scan can (``draws_in_c``), in the order the turns were
        started, else now: ``rng`` is not to be drawn from elsewhere while a scan is
        pending. Without a pipe (``ScanPipe.open()`` gives None where there is none)
        the scan is made now."""
        job = self._job(world, pose_at, t0, rng)
        if job is None:
            return PendingScan(self.scan_numpy(world, pose_at, t0, rng))
        if pipe is None:
            job.run()
            return PendingScan(self._made(t0, job, pose_at))
        pipe.submit(job)
        return PendingScan(None, lambda: self._made(t0, pipe.wait(job), pose_at))

    def scan_numpy(self, world: World, pose_at: PoseAt, t0: float, rng: np.random.Generator | None = None
                   ) -> LaserScan:
        """``scan`` in numpy (its casts ``world.cast``'s): the reference."""
        m = self.model
        times, q2 = self.samples(world, pose_at, t0, rng)
        beams, multiple = self.beams, self._multiple
        start_bin = self._first_bins(np.arange(m.samples) * 360.0 / m.samples)
        valid = np.flatnonzero(q2 != 0)
        # bin b holds the last sample with a return whose bins (start .. start + multiple - 1,
        # the last bin for those past it) reach b
        b = np.arange(beams)
        if valid.size == 0:
            node = np.full(beams, -1)
        else:
            last = np.searchsorted(start_bin[valid], b, side="right") - 1
            node = np.where(last >= 0, valid[np.maximum(last, 0)], -1)
        reaches = (node >= 0) & (start_bin[np.maximum(node, 0)] + multiple - 1 >= b)
        bins_q2 = np.where(reaches, q2[np.maximum(node, 0)], 0)
        bins_t = np.where(reaches, times[np.maximum(node, 0)], np.nan)
        ranges = (bins_q2.astype(np.float32) / np.float32(4.0)) / np.float32(1000.0)
        ranges = np.where(bins_q2 == 0, np.float32(np.inf), ranges).astype(np.float32)
        intensities = np.where(bins_q2 == 0, 0.0, m.intensity).astype(np.float32)
        return self._message(t0, ranges, intensities, bins_t)

    def _made(self, t0: float, job: ScanJob, pose_at: PoseAt) -> LaserScan:
        """The scan of a job made (a ``MotionTrack`` keeping the knots it integrated)."""
        if isinstance(pose_at, MotionTrack) and job.integrated:
            pose_at._integrated(job)
        if self._c_reverses:                # back to the device's order
            return self._message(t0, job.ranges[::-1], job.intensities[::-1], job.beam_time[::-1])
        return self._message(t0, job.ranges, job.intensities, job.beam_time)

    def _message(self, t0: float, ranges: np.ndarray, intensities: np.ndarray, beam_time: np.ndarray
                 ) -> LaserScan:
        """The scan the driver publishes of the turn's bins (in the device's order)."""
        m, driver = self.model, self.driver
        scan_time = 1.0 / m.scan_hz
        told = self.mount.driver_inverted
        if driver.angle_compensate:
            f = driver.publish(ranges, intensities, beam_time, (0.0, driver.compensated_span_deg),
                               scan_time, told)
        else:                               # every sample its own beam, at its own time
            f = driver.publish_raw(ranges, intensities, self.times(t0), self._device_angles()[0],
                                   scan_time, told)
        f32 = np.float32
        return LaserScan(t0, self.frame_id, f.angle_min, f.angle_max, f.angle_increment, f.time_increment,
                         float(f32(scan_time)), f.range_min, float(f32(m.range_max)), f.ranges,
                         f.intensities, f.beam_time)


def lidar_named(name: str) -> Lidar:
    """The lidar model ``name`` (``MODELS``: rplidar_s3) on the seed's mount
    (``SEED_MOUNT``: 0.20 m ahead of the axle, 0.30 m up); a ``ValueError`` names the
    models for any other."""
    if name not in MODELS:
        raise ValueError(f"must be one of {', '.join(MODELS)}")
    return Lidar(MODELS[name], SEED_MOUNT)


#: The keys of a lidar's configuration: a URL's ``lidar_*`` options, a chair file's
#: ``[lidar]`` table.
LIDAR_KEYS = ("model", "mount", "driver", "inverted", "angle_compensate")


def flag(text: str) -> bool:
    """``true``/``false`` (or ``1``/``0``); a ``ValueError`` for anything else."""
    value = {"true": True, "1": True, "false": False, "0": False}.get(text.strip().lower())
    if value is None:
        raise ValueError(f"{text!r} is not true or false")
    return value


def configured_lidar(model: str = "rplidar_s3", mount: str | LidarMount | None = None,
                     driver: str = "sllidar_ros2", inverted: bool = False,
                     angle_compensate: bool = True) -> Lidar:
    """The lidar ``model`` (``MODELS``) on ``mount`` (a ``LidarMount``, its
    ``x,y,z,roll,pitch,yaw`` text for ``parse_mount``, or None: the seed's,
    ``SEED_MOUNT``), published by ``driver`` (``DRIVERS``) with its ``inverted`` and
    ``angle_compensate`` parameters. A ``ValueError`` names the bad value."""
    if model not in MODELS:
        raise ValueError(f"lidar model {model!r}: must be one of {', '.join(MODELS)}")
    if isinstance(mount, str):
        place = parse_mount(mount, inverted)
    else:
        place = dataclasses.replace(mount or SEED_MOUNT, driver_inverted=inverted)
    return Lidar(MODELS[model], place, driver=LidarDriver(driver, angle_compensate))


def lidar_from_table(table: Mapping[str, object]) -> Lidar:
    """``configured_lidar`` of a chair file's ``[lidar]`` table (``LIDAR_KEYS``: ``model``
    and ``driver`` strings, ``mount`` its text or an array of six numbers, ``inverted``
    and ``angle_compensate`` true or false; each may be left out). A ``ValueError``
    names an unknown key or a value of the wrong kind."""
    for key in table:
        if key not in LIDAR_KEYS:
            raise ValueError(f"unknown key {key!r} (known: {', '.join(LIDAR_KEYS)})")
    kinds = {"model": str, "driver": str, "inverted": bool, "angle_compensate": bool}
    for key, kind in kinds.items():
        if key in table and not isinstance(table[key], kind):
            what = "true or false" if kind is bool else "a string"
            raise ValueError(f"{key} = {table[key]!r} is not {what}")
    mount = table.get("mount")
    if isinstance(mount, list):
        if len(mount) != 6 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in mount):
            raise ValueError(f"mount = {mount!r} is not six numbers x, y, z, roll, pitch, yaw (m and deg)")
        mount = ",".join(repr(float(v)) for v in mount)
    if mount is not None and not isinstance(mount, str):
        raise ValueError(f"mount = {mount!r} is not \"x,y,z,roll,pitch,yaw\" or an array of six numbers")
    return configured_lidar(str(table.get("model", "rplidar_s3")), mount,
                            str(table.get("driver", "sllidar_ros2")), bool(table.get("inverted", False)),
                            bool(table.get("angle_compensate", True)))
