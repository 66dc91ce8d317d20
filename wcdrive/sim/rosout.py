"""A simulated run as ROS 2 messages (``wcdrive.ros2.bridge``): ``wcdrive sim --mcap FILE``
writes them into an MCAP file, ``wcdrive sim --live`` serves them to Foxglove at the
pace of the simulated clock.

Every stamp is the board's clock: the simulated Mega's, in s from its power-on (the
cycle of the control tick, or of the line's last byte, over 16 MHz). Per control tick
(20 Hz): ``/odom`` (the host's position-based wheel odometry; its twist from the tick's
counts; seed 000's ekf.yaml covariances), ``/tf``, ``/joint_states`` (wheel angles from
the counts, the firmware's filtered speeds), ``/ground_truth`` (the plant's pose, its
twist from consecutive poses) and ``/odometry/filtered`` (the EKF on wheel velocities,
when the run has one); ``/imu`` per gyro sample (400 Hz); ``/cmd_vel``
(``TwistStamped``) per velocity command the host sent; ``/diagnostics/serial`` per line
the board sent.

A run among walls adds ``/map`` at 0 s, once (latched: ``bridge.QOS``): the world's ROS
map, or a hand-written world drawn into 5 cm cells (``World.occupancy``), in the world's
``map`` frame, where the chair started at the scenario's ``start``. A run with a lidar
adds ``/tf_static`` at 0 s, once (latched): base_link -> laser, the mount's offset, yaw
and the laser frame's roll (pi for a head-down mount whose driver is not told); and
``/scan`` per turn of the head (10 Hz), stamped at its first beam as the driver stamps
it, with the driver's ``time_increment`` and ``scan_time``.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from wcdrive.host.odometry import UNUSED, OdometryParams
from wcdrive.plant.params import ChairParams
from wcdrive.plant.world import World
from wcdrive.ros2 import bridge as ros2
from wcdrive.sim.result import SimResult

#: Seed 000's ekf.yaml: odom0_pose_covariance and odom0_twist_covariance (x, y, z,
#: roll, pitch, yaw; 1e6 = "not used").
ODOM_POSE_COVARIANCE = np.diag([0.05, 0.05, UNUSED, UNUSED, UNUSED, UNUSED])
ODOM_TWIST_COVARIANCE = np.diag([0.1, 0.1, UNUSED, UNUSED, UNUSED, UNUSED])

Message = tuple[float, str, dict[str, Any]]


def _ticks(result: SimResult, params: ChairParams) -> Iterator[Message]:
    op = OdometryParams(wheel_radius=params.wheel_radius, wheelbase=params.wheelbase,
                        counts_per_rev=params.counts_per_rev)
    per_count = 2.0 * math.pi / op.counts_per_rev
    board, truth, odometry = result.board, result.truth, result.odometry
    t = board.tick_time
    counts = board.counts
    for i in range(len(t)):
        ti = float(t[i])
        x, y, th = (float(v) for v in odometry.wheel[i])
        v = w = 0.0
        gv = gw = 0.0
        if i > 0 and t[i] > t[i - 1]:
            dt = float(t[i] - t[i - 1])
            d_left = -(counts[i, 0] - counts[i - 1, 0]) * per_count * op.wheel_radius
            d_right = (counts[i, 1] - counts[i - 1, 1]) * per_count * op.wheel_radius
            v, w = 0.5 * (d_left + d_right) / dt, (d_right - d_left) / op.wheelbase / dt
            tx0, ty0, tt0 = truth.pose[i - 1]
            tx1, ty1, tt1 = truth.pose[i]
            gv = ((tx1 - tx0) * math.cos(tt1) + (ty1 - ty0) * math.sin(tt1)) / dt
            gw = math.remainder(tt1 - tt0, 2 * math.pi) / dt
        yield ti, "/odom", ros2.odometry(ti, x, y, th, v, w, ODOM_POSE_COVARIANCE, ODOM_TWIST_COVARIANCE)
        yield ti, "/tf", ros2.tf(ti, x, y, th)
        yield ti, "/joint_states", ros2.joint_state(
            ti, (-float(counts[i, 0]) * per_count, float(counts[i, 1]) * per_count),
            (float(board.measured[i, 0]), float(board.measured[i, 1])))
        tx, ty, tth = (float(c) for c in truth.pose[i])
        yield ti, "/ground_truth", ros2.odometry(ti, tx, ty, tth, gv, gw)
        if odometry.ekf_vel is not None:
            ex, ey, eth = (float(c) for c in odometry.ekf_vel[i])
            yield ti, "/odometry/filtered", ros2.odometry(ti, ex, ey, eth, 0.0, 0.0)


def _imu(result: SimResult, params: ChairParams) -> Iterator[Message]:
    variance = math.radians(params.gyro_noise_dps) ** 2
    for t, rate in zip(result.odometry.gyro_time, result.odometry.gyro_rate, strict=True):
        yield float(t), "/imu", ros2.imu(float(t), float(rate), variance)


def _static(result: SimResult) -> Iterator[Message]:
    """``/map`` and ``/tf_static`` at 0 s (module docstring)."""
    world = result.world
    if world is not None and world.walled:
        grid = world.grid if world.grid is not None else World(world.segments, world.circles).occupancy()
        yield 0.0, "/map", ros2.occupancy_grid(0.0, grid)
    if result.lidar is not None:
        lidar = result.lidar.lidar
        m = lidar.mount
        yield 0.0, "/tf_static", ros2.tf_static(0.0, lidar.frame_id, m.x, m.y, m.z, math.radians(m.yaw_deg),
                                                 m.tf_roll)


def _scans(result: SimResult) -> Iterator[Message]:
    for scan in [] if result.lidar is None else result.lidar.scans:
        yield scan.stamp, "/scan", ros2.laser_scan(scan)


def messages(result: SimResult, params: ChairParams | None = None) -> Iterator[Message]:
    """(board time s, topic, message) for every message of the run, in time order."""
    params = params or ChairParams()
    streams = [
        _static(result),
        _ticks(result, params),
        _imu(result, params),
        _scans(result),
        ((t, "/cmd_vel", ros2.twist_stamped(t, v, w)) for t, v, w in result.link.cmd_vel),
        ((t, "/diagnostics/serial", ros2.serial_line(t, line)) for t, line in result.link.lines),
    ]
    yield from heapq.merge(*streams, key=lambda m: m[0])


def write_mcap(result: SimResult, path: str | Path, params: ChairParams | None = None) -> dict[str, int]:
    """Writes the run into an MCAP file; returns the message count per topic."""
    sink = ros2.McapSink(path)
    counts: dict[str, int] = {}
    try:
        for t, topic, msg in messages(result, params):
            sink.publish(topic, msg, t)
            counts[topic] = counts.get(topic, 0) + 1
    finally:
        sink.close()
    return counts


#: s of the board's clock between two repeats of the latched messages in ``serve``.
LATCHED_REPEAT_S = 1.0


def serve(result: SimResult, sink: ros2.Sink, params: ChairParams | None = None,
          speed: float = 1.0) -> int:
    """Publishes the run on ``sink`` paced by the board's clock (``speed`` times the
    wall clock; 0: as fast as it goes); returns the number of messages. A live view has
    no latching: a client that connects after ``/map`` and ``/tf_static`` went out would
    never draw the map nor place the laser, so the latched topics' last messages go out
    again every ``LATCHED_REPEAT_S`` s of the run."""
    start = time.monotonic()
    n = 0
    latched: dict[str, dict] = {}
    repeat_at = math.inf
    for t, topic, msg in messages(result, params):
        if speed > 0:
            delay = start + t / speed - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        while latched and t >= repeat_at:
            for name, again in latched.items():
                sink.publish(name, again, repeat_at)
                n += 1
            repeat_at += LATCHED_REPEAT_S
        if ros2.qos(topic).transient_local:
            if not latched:
                repeat_at = t + LATCHED_REPEAT_S
            latched[topic] = msg
        sink.publish(topic, msg, t)
        n += 1
    return n
