"""The host of a ``wcdrive sim`` run, from the library's host parts: ``SimHost`` reads
the board's bytes and keeps the odometries, ``Pilot`` steers a closed-loop run.

``SimHost`` turns the bytes into messages with ``LineDecoder`` (``wcdrive.protocol.codec``,
as ``wcdrive.host.session.Session`` does for ``connect()``) and integrates each
``Feedback``'s counts with ``WheelOdometry`` (``wcdrive.host.odometry``, the integrator
``wcdrive.host.telemetry.TelemetryHub`` keeps), three times: by position (the library's
default), by velocity, and by position with the heading from the gyro
(``GyroIntegrator``); on request also the seeds' EKFs (``wcdrive.navigation.ekf``).

What it leaves out of ``TelemetryHub``, on purpose: the board clock (a line's time is the
simulated cycle of its last byte, exact), the re-baselining after a board reset (the
estimates show what the counts say), the subscribers and the history ring. Those cost
about 39 us a feedback line in ``TelemetryHub.deliver``, most of the 43 us a control
tick of a whole run takes.
"""

from __future__ import annotations

import bisect

from wcdrive.boards.port_loop import F_CPU
from wcdrive.host.odometry import GyroIntegrator, OdometryParams, WheelOdometry
from wcdrive.navigation.ekf import Ekf2D, EkfConfig
from wcdrive.navigation.pure_pursuit import PurePursuit
from wcdrive.plant import Gyro
from wcdrive.plant.params import ChairParams
from wcdrive.protocol.codec import Feedback, LineDecoder
from wcdrive.protocol.motion import velocity_command
from wcdrive.sim.scenario import MOTION_START_S, Scenario

Pose = tuple[float, float, float]


class SimHost:
    """The navigation host (module docstring): ``receive`` the board's bytes, ``poses``
    the five estimates; ``line_counts`` the board's lines by kind (``feedback``,
    ``error``, ``event``, ``other``)."""

    def __init__(self, params: ChairParams, gyro: Gyro, ekf: bool = False) -> None:
        op = OdometryParams(wheel_radius=params.wheel_radius, wheelbase=params.wheelbase,
                            counts_per_rev=params.counts_per_rev)
        self.decoder = LineDecoder()
        self.position = WheelOdometry(op, "position")
        self.velocity = WheelOdometry(op, "velocity")
        self.gyro_odom = WheelOdometry(op, "position")
        self.gyro = gyro
        self.integrator = GyroIntegrator()
        self.ekf = Ekf2D()
        self.ekf_vel = Ekf2D(EkfConfig.wheel_velocities())
        #: The EKFs run only when asked (``run(..., ekf=True)``): at the gyro's 400 Hz they
        #: take 9 times as long as the rest of the run.
        self.ekfs: tuple[Ekf2D, ...] = (self.ekf, self.ekf_vel) if ekf else ()
        self._gyro_index = 0
        self._idle_ekf_poses: tuple[Pose, Pose] | None = None
        self.line_counts = {"feedback": 0, "error": 0, "event": 0, "other": 0}

    def receive(self, t: float, data: bytes) -> None:
        """The board's bytes ``data``, their last one received at ``t`` (s): each complete
        feedback line moves the odometries on, with the gyro's samples up to ``t``."""
        for msg in self.decoder.feed(data):
            if isinstance(msg, Feedback):
                self.line_counts["feedback"] += 1
                times, rates = self.gyro.times, self.gyro.rates
                upto = bisect.bisect_right(times, t, self._gyro_index)
                if not self.ekfs:
                    self.integrator.add_many(times, rates, self._gyro_index, upto)
                for i in range(self._gyro_index, upto) if self.ekfs else ():
                    self.integrator.add(times[i], rates[i])
                    for ekf in self.ekfs:
                        ekf.imu(times[i], self.integrator.heading, rates[i])
                self._gyro_index = upto
                self.position.integrate(t, msg.count_left, msg.count_right)
                self.velocity.integrate(t, msg.count_left, msg.count_right)
                v = self.velocity
                for ekf in self.ekfs:
                    ekf.odometry(t, v.pose.x, v.pose.y, v.pose.theta, v.linear, v.angular)
                self.gyro_odom.use_gyro_heading(self.integrator.heading_at(t))
                self.gyro_odom.integrate(t, msg.count_left, msg.count_right)
            else:
                key = type(msg).__name__.lower()
                self.line_counts[key if key in self.line_counts else "other"] += 1

    def poses(self) -> tuple[Pose, Pose, Pose, Pose, Pose]:
        """The estimates now, each (x, y, heading): position, velocity and gyro-heading
        odometry, the two EKFs (their first pose when they do not run)."""
        p, v, g = self.position.pose, self.velocity.pose, self.gyro_odom.pose
        if self.ekfs:
            ekf, ekf_vel = self.ekf.pose, self.ekf_vel.pose
        else:                           # filters that never run: their first pose, kept
            if self._idle_ekf_poses is None:
                self._idle_ekf_poses = (self.ekf.pose, self.ekf_vel.pose)
            ekf, ekf_vel = self._idle_ekf_poses
        return (p.x, p.y, p.theta), (v.x, v.y, v.theta), (g.x, g.y, g.theta), ekf, ekf_vel


class Pilot:
    """The closed-loop host: every host period, a ``cmdvel`` from pure pursuit
    (``wcdrive.navigation.pure_pursuit``) on the host's own estimate (wheel odometry or the EKF);
    after the goal, stops for ``settle_s``. Times are in 16 MHz cycles."""

    def __init__(self, scenario: Scenario, host: SimHost) -> None:
        assert scenario.path is not None
        self.ctl = PurePursuit(scenario.path, scenario.follow)
        self.host = host
        self.localization = scenario.follow.localization
        self.period = round(F_CPU / scenario.host_rate_hz)
        self.next = round((scenario.host_offset_s + MOTION_START_S) * F_CPU)
        self.settle = round(scenario.settle_s * F_CPU)
        self.sent: list[tuple[int, bytes]] = []
        self.done_at: int | None = None

    def pose(self) -> Pose:
        """The estimate the pilot steers by."""
        if self.localization == "ekf":
            return self.host.ekf_vel.pose
        p = self.host.position.pose
        return p.x, p.y, p.theta

    def step(self) -> tuple[int, bytes]:
        """The command due at ``next``; moves ``next`` on a period."""
        cycle = self.next
        v, w, done = self.ctl.command(*self.pose())
        if done and self.done_at is None:
            self.done_at = cycle
        data = velocity_command(v, w)
        self.sent.append((cycle, data))
        self.next += self.period
        return cycle, data

    def finished(self) -> bool:
        """The goal was reached and the chair has had ``settle_s`` to stop."""
        return self.done_at is not None and self.next >= self.done_at + self.settle
