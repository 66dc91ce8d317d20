"""Wheel odometry from encoder counts, as in the FRA532 report, with covariance.

``WheelOdometry(params, method=...)`` integrates (time, left count, right count)
samples. Both methods step by the wheels' distance increments since the last sample
(``v dt``), so sample-time jitter does not enter the pose; they differ in the heading:

* ``method="position"`` (the default): the midpoint heading,
  ``x += d cos(theta + dtheta/2)``.
* ``method="velocity"``: Euler steps with the heading at the start of the step,
  ``x += v cos(theta) dt`` (the guide's section 2.0.6 and the report's type 2).
* ``use_gyro_heading(heading)``: the next update takes its heading from an integrated
  z-gyro (``GyroIntegrator``) instead of the wheel difference, so wheel slip does not
  turn the estimate.

Covariances follow the seed's ekf.yaml conventions: a 6x6 row-major matrix over
(x, y, z, roll, pitch, yaw) for pose and (vx, vy, vz, vroll, vpitch, vyaw) for twist,
with the unused 3D terms set large so that a 2D filter ignores them.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from wcdrive.protocol.spec import real

#: Variance given to the unused 3D terms (z, roll, pitch): "do not use".
UNUSED = 1e6
#: ``WheelOdometry.integrate`` keeps at most this many steps (32 bytes each) before it
#: propagates their covariance, whether or not it is read.
PENDING_STEPS = 1 << 16


@dataclass(slots=True)
class Pose2D:
    """x, y (m) and heading ``theta`` (rad, counter-clockwise) in the odometry frame."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


@dataclass
class OdometryParams:
    """The geometry (the spec's, by default) and the noise model."""

    wheel_radius: float = real("WHEEL_RADIUS")
    wheelbase: float = real("WHEELBASE")
    counts_per_rev: int = round(real("CPR"))
    #: Per-metre variance growth of each wheel's distance (slip, radius error).
    distance_variance_per_m: float = 1e-4
    #: Twist variances (vx, vyaw) reported with each estimate.
    twist_variance: tuple[float, float] = (0.1**2, 0.1**2)


@dataclass
class OdometryEstimate:
    """One estimate: its time, the pose, linear (m/s) and angular (rad/s) speed over the
    last interval, and 6x6 pose and twist covariances (the ekf.yaml layout)."""

    time: float
    pose: Pose2D
    linear: float
    angular: float
    pose_covariance: np.ndarray = field(repr=False)
    twist_covariance: np.ndarray = field(repr=False)
    #: The board's clock at the last tick (s, continuous over resets; None: not known),
    #: and the host time it maps to (``wcdrive.host.boardclock``).
    board_time: float | None = None
    stamp: float | None = None


def _cov6(xx: float, yy: float, tt: float, xy: float = 0.0, xt: float = 0.0, yt: float = 0.0) -> np.ndarray:
    c = np.diag([xx, yy, UNUSED, UNUSED, UNUSED, tt])
    c[0, 1] = c[1, 0] = xy
    c[0, 5] = c[5, 0] = xt
    c[1, 5] = c[5, 1] = yt
    return c


class WheelOdometry:
    """Integrates (time, left count, right count) samples, the left count mirrored
    as the firmware reports it. ``method`` is "position" or "velocity"."""

    def __init__(self, params: OdometryParams | None = None, method: str = "position") -> None:
        if method not in ("position", "velocity"):
            raise ValueError("method must be 'position' or 'velocity'")
        self.p = params or OdometryParams()
        self.method = method
        self.pose = Pose2D()
        self._cov_matrix = np.zeros((3, 3))
        #: Steps whose covariance propagation waits until a covariance is read
        #: (``_cov``): the same numpy operations in the same order, so the same bits,
        #: paid only by those who read it.
        self._pending = array("d")           # (d, heading, d_left, d_right) per step
        self._last: tuple[float, int, int] | None = None
        self._rad_per_count = 2.0 * math.pi / self.p.counts_per_rev
        self.linear = 0.0
        self.angular = 0.0
        self._gyro_heading: float | None = None

    def rebaseline(self) -> None:
        """The counts restarted (a board reset): the next sample only sets the starting
        counts, and the pose carries on from where it is."""
        self._last = None

    def use_gyro_heading(self, heading: float) -> None:
        """From now on, the next update takes this heading (from an integrated gyro)."""
        self._gyro_heading = heading

    def update(self, time: float, count_left: int, count_right: int) -> OdometryEstimate:
        """One sample (``time`` in s, the counts as the firmware reports them); returns
        the estimate. The first sample only sets the starting counts."""
        self.integrate(time, count_left, count_right)
        return self.estimate(time)

    def integrate(self, time: float, count_left: int, count_right: int) -> None:
        """``update`` without building the estimate: the pose and the speeds move on
        exactly as ``update`` moves them, and so does the covariance, when it is next
        read (``estimate``) or after ``PENDING_STEPS`` steps. For a caller that reads
        the covariance seldom or never (``wcdrive sim``'s host); one that reads it at
        every sample calls ``update``."""
        if self._last is None:
            self._last = (time, count_left, count_right)
            return
        t0, l0, r0 = self._last
        self._last = (time, count_left, count_right)
        dt = time - t0
        p, pose, per_count = self.p, self.pose, self._rad_per_count
        d_left = -(count_left - l0) * per_count * p.wheel_radius     # mirrored
        d_right = (count_right - r0) * per_count * p.wheel_radius
        d = 0.5 * (d_left + d_right)
        th = pose.theta
        if self._gyro_heading is not None:
            dtheta = self._gyro_heading - th
            self._gyro_heading = None
        else:
            dtheta = (d_right - d_left) / p.wheelbase
        heading = th + 0.5 * dtheta if self.method == "position" else th
        pose.x += d * math.cos(heading)
        pose.y += d * math.sin(heading)
        pose.theta = th + dtheta
        if dt > 0:
            self.linear, self.angular = d / dt, dtheta / dt
        pending = self._pending
        pending.extend((d, heading, d_left, d_right))
        if len(pending) >= 4 * PENDING_STEPS:
            self._flush()

    @property
    def _cov(self) -> np.ndarray:
        """The 3x3 pose covariance (x, y, theta), every pending step propagated."""
        if self._pending:
            self._flush()
        return self._cov_matrix

    def _flush(self) -> None:
        pending, self._pending = self._pending, array("d")
        for i in range(0, len(pending), 4):
            self._propagate(pending[i], pending[i + 1], pending[i + 2], pending[i + 3])

    def _propagate(self, d: float, heading: float, d_left: float, d_right: float) -> None:
        """First-order propagation of the wheel distance noise into the pose."""
        k = self.p.distance_variance_per_m
        q = np.diag([k * abs(d_left), k * abs(d_right)])
        c, s, base = math.cos(heading), math.sin(heading), self.p.wheelbase
        f = np.array([[1.0, 0.0, -d * s], [0.0, 1.0, d * c], [0.0, 0.0, 1.0]])
        g = np.array([[0.5 * c, 0.5 * c], [0.5 * s, 0.5 * s], [-1.0 / base, 1.0 / base]])
        self._cov_matrix = f @ self._cov_matrix @ f.T + g @ q @ g.T

    def estimate(self, time: float) -> OdometryEstimate:
        """The pose, speeds and covariances now, stamped ``time``."""
        c = self._cov
        pose_cov = _cov6(c[0, 0], c[1, 1], c[2, 2], c[0, 1], c[0, 2], c[1, 2])
        vx, vyaw = self.p.twist_variance
        twist_cov = _cov6(vx, UNUSED, vyaw)
        return OdometryEstimate(time, Pose2D(self.pose.x, self.pose.y, self.pose.theta),
                                self.linear, self.angular, pose_cov, twist_cov)


class GyroIntegrator:
    """Integrates z-gyro samples (trapezoid) into a heading."""

    def __init__(self, heading: float = 0.0) -> None:
        self.heading = heading
        self._last: tuple[float, float] | None = None

    def add(self, time: float, rate: float) -> None:
        """One sample: ``rate`` rad/s at ``time`` s."""
        if self._last is not None:
            t0, r0 = self._last
            self.heading += 0.5 * (rate + r0) * (time - t0)
        self._last = (time, rate)

    def add_many(self, times: Sequence[float], rates: Sequence[float], start: int = 0,
                 stop: int | None = None) -> None:
        """The samples ``times[start:stop]``, ``rates[start:stop]``, each as ``add``
        takes it (the same sums in the same order)."""
        stop = len(times) if stop is None else stop
        if start >= stop:
            return
        heading = self.heading
        if self._last is None:             # the first sample only starts the sums
            self._last = (times[start], rates[start])
            start += 1
        t0, r0 = self._last
        for time, rate in zip(times[start:stop], rates[start:stop], strict=True):
            heading += 0.5 * (rate + r0) * (time - t0)
            t0, r0 = time, rate
        self.heading, self._last = heading, (t0, r0)

    def heading_at(self, time: float) -> float:
        """The heading at ``time`` (extrapolated from the last sample)."""
        if self._last is None:
            return self.heading
        t0, r0 = self._last
        return self.heading + r0 * (time - t0)
