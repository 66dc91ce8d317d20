"""The seeds' localisation: an EKF that fuses wheel odometry and a z-gyro the way
robot_localization's ``ekf_node`` does in ``two_d_mode`` (seed 000, the wheelchair
navigation guide, section 4.2: ``ekf.yaml``), built on ``filterpy``'s
``ExtendedKalmanFilter``.

The state is robot_localization's 15-state vector with the 3D terms dropped, as
``two_d_mode`` pins them to 0: ``[x, y, yaw, vx, vy, vyaw, ax, ay]`` (world-frame pose,
body-frame velocities and accelerations). The motion model is robot_localization's
omnidirectional one, its Jacobian included; the process noise is the seed's
``process_noise_covariance`` scaled by the step, as robot_localization scales it.

Which state each source fuses is the seed's configuration (``EkfConfig``):

* ``odom0`` (the wheels): ``x, y`` and ``vx`` (``odom0_config``: position and forward
  speed, never yaw: "NO yaw from wheels (drift!)"), with the seed's
  ``odom0_pose_covariance`` (0.05) and ``odom0_twist_covariance`` (0.1);
* ``imu0`` (the gyro): ``yaw`` and ``vyaw`` (``imu0_config``), with
  ``imu0_orientation_covariance`` (0.05) and ``imu0_angular_velocity_covariance``
  (0.02). A gyro reports no orientation, so the yaw is the gyro's integral
  (``wcdrive.host.odometry.GyroIntegrator``), as the D455's own filter gives in the seed.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: The state's names, in order.
STATES = ("x", "y", "yaw", "vx", "vy", "vyaw", "ax", "ay")
X, Y, YAW, VX, VY, VYAW, AX, AY = range(8)
#: robot_localization's 15-vector order for a ``*_config`` array; these are its 2D terms.
_RL_INDEX = {0: X, 1: Y, 5: YAW, 6: VX, 7: VY, 11: VYAW, 12: AX, 13: AY}


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _selected(config: tuple[bool, ...]) -> list[int]:
    """The 2D states a robot_localization ``*_config`` array (15 booleans) fuses."""
    if len(config) != 15:
        raise ValueError("a robot_localization *_config has 15 entries")
    return [_RL_INDEX[i] for i, used in enumerate(config) if used and i in _RL_INDEX]


@dataclass(frozen=True)
class EkfConfig:
    """The seed's ``ekf.yaml`` (seed 000, listings 19 to 21), 2D terms."""

    #: x, y, z, roll, pitch, yaw, vx, vy, vz, vroll, vpitch, vyaw, ax, ay, az
    odom0_config: tuple[bool, ...] = (True, True, False, False, False, False,
                                      True, False, False, False, False, False,
                                      False, False, False)
    imu0_config: tuple[bool, ...] = (False, False, False, False, False, True,
                                     False, False, False, False, False, True,
                                     False, False, False)
    #: Measurement variances by 2D state (the seed's covariance diagonals).
    odom0_variance: tuple[tuple[str, float], ...] = (("x", 0.05), ("y", 0.05), ("yaw", 1e6),
                                                     ("vx", 0.1), ("vy", 0.1), ("vyaw", 1e6))
    imu0_variance: tuple[tuple[str, float], ...] = (("yaw", 0.05), ("vyaw", 0.02))
    #: ``process_noise_covariance`` diagonal: x, y, yaw, vx, vy, vyaw, ax, ay.
    process_noise: tuple[float, ...] = (0.05, 0.05, 0.06, 0.1, 0.1, 0.1, 0.15, 0.15)
    #: ``initial_estimate_covariance`` (robot_localization's default, 1e-9).
    initial_variance: float = 1e-9

    @classmethod
    def wheel_velocities(cls) -> EkfConfig:
        """Seed 002's scheme in robot_localization's terms: the wheels give only their
        velocities (``vx``, and ``vy`` = 0 of a chair that cannot slide sideways), the
        gyro the yaw and its rate; seed 000's covariances and process noise. Seed
        000's ``x, y`` from the wheels carry every slip of the wheels into the
        filter; this does not."""
        return cls(odom0_config=(False, False, False, False, False, False,
                                 True, True, False, False, False, False,
                                 False, False, False))


@functools.cache
def _omni_ekf() -> Any:
    """filterpy's EKF with the nonlinear state transition: ``predict`` propagates the
    covariance with ``F`` (the Jacobian) and ``Q``, and the state with ``f``. Made on
    first use: filterpy imports scipy, half a second that every CLI start would pay."""
    from filterpy.kalman import ExtendedKalmanFilter

    class _OmniEkf(ExtendedKalmanFilter):
        f: np.ndarray | None = None
        x: np.ndarray

        def predict_x(self, u: object = 0) -> None:
            assert self.f is not None
            state: np.ndarray = self.f @ self.x
            state[YAW, 0] = _wrap(float(state[YAW, 0]))
            self.x = state

    return _OmniEkf


class Ekf2D:
    """robot_localization's EKF in ``two_d_mode`` (module docstring). Feed it
    measurements in time order: ``odometry(t, x, y, yaw, vx, vyaw)`` and
    ``imu(t, yaw, vyaw)``; each predicts to ``t`` and fuses the configured states."""

    def __init__(self, config: EkfConfig | None = None) -> None:
        self.config = config or EkfConfig()
        self.kf = _omni_ekf()(dim_x=8, dim_z=1)
        self.kf.x = np.zeros((8, 1))
        self.kf.P = np.eye(8) * self.config.initial_variance
        self._q = np.diag(self.config.process_noise)
        self._odom_states = _selected(self.config.odom0_config)
        self._imu_states = _selected(self.config.imu0_config)
        self._odom_var = {STATES.index(k): v for k, v in self.config.odom0_variance}
        self._imu_var = {STATES.index(k): v for k, v in self.config.imu0_variance}
        self.time: float | None = None

    @property
    def pose(self) -> tuple[float, float, float]:
        """x, y (m), yaw (rad) now."""
        s = self.kf.x[:, 0]
        return float(s[X]), float(s[Y]), float(s[YAW])

    @property
    def twist(self) -> tuple[float, float]:
        """Forward speed (m/s) and yaw rate (rad/s) now."""
        s = self.kf.x[:, 0]
        return float(s[VX]), float(s[VYAW])

    def predict(self, t: float) -> None:
        """Runs the motion model forward to ``t``."""
        if self.time is None:
            self.time = t
            return
        dt = t - self.time
        if dt <= 0:
            return
        self.time = t
        s = self.kf.x[:, 0]
        c, sn = math.cos(s[YAW]), math.sin(s[YAW])
        vx, vy, ax, ay = s[VX], s[VY], s[AX], s[AY]
        h = 0.5 * dt * dt
        f = np.eye(8)
        f[X, VX], f[X, VY], f[X, AX], f[X, AY] = c * dt, -sn * dt, c * h, -sn * h
        f[Y, VX], f[Y, VY], f[Y, AX], f[Y, AY] = sn * dt, c * dt, sn * h, c * h
        f[YAW, VYAW] = dt
        f[VX, AX] = dt
        f[VY, AY] = dt
        jac = f.copy()               # the Jacobian: f plus d/dyaw of the position rows
        jac[X, YAW] = (-sn * vx - c * vy) * dt + (-sn * ax - c * ay) * h
        jac[Y, YAW] = (c * vx - sn * vy) * dt + (c * ax - sn * ay) * h
        self.kf.f = f
        self.kf.F = jac
        self.kf.Q = self._q * dt
        self.kf.predict()

    def _fuse(self, states: list[int], values: dict[int, float], variance: dict[int, float]) -> None:
        used = [i for i in states if i in values]
        if not used:
            return
        h = np.zeros((len(used), 8))
        for row, i in enumerate(used):
            h[row, i] = 1.0
        z = np.array([[values[i]] for i in used])
        r = np.diag([variance.get(i, 1e6) for i in used])

        def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            d = a - b
            for row, i in enumerate(used):
                if i == YAW:
                    d[row, 0] = _wrap(float(d[row, 0]))
            return d

        self.kf.update(z, lambda _x: h, lambda x: h @ x, R=r, residual=residual)
        self.kf.x[YAW, 0] = _wrap(self.kf.x[YAW, 0])

    def odometry(self, t: float, x: float, y: float, yaw: float, vx: float, vyaw: float) -> None:
        """A wheel odometry message at ``t``: fuses the states ``odom0_config`` names."""
        self.predict(t)
        self._fuse(self._odom_states, {X: x, Y: y, YAW: yaw, VX: vx, VY: 0.0, VYAW: vyaw},
                   self._odom_var)

    def imu(self, t: float, yaw: float, vyaw: float) -> None:
        """A gyro sample at ``t`` (``yaw`` its integral): fuses ``imu0_config``'s states."""
        self.predict(t)
        self._fuse(self._imu_states, {YAW: yaw, VYAW: vyaw}, self._imu_var)

    def pose_measurement(self, t: float, x: float, y: float, yaw: float,
                         variance: tuple[float, float, float]) -> None:
        """A pose at ``t`` from a third source (scan matching: ``wcdrive.sim.compare``),
        ``x``, ``y`` and ``yaw`` fused with the given variances (m^2, m^2, rad^2)."""
        self.predict(t)
        self._fuse([X, Y, YAW], {X: x, Y: y, YAW: yaw}, dict(zip((X, Y, YAW), variance, strict=True)))
