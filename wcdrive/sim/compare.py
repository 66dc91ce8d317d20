"""Seed 002's comparison on a simulated run with a lidar: wheel odometry, the EKF, ICP
lidar odometry seeded by the wheels, and ICP seeded by the EKF ("ICP + EKF"), each
against the plant's ground truth.

    result = runner.run(scenario.load("room_lidar"), ekf=True)
    table = compare(result)               # {"wheel": Errors, "ekf": ..., "icp": ..., "fused": ...}

The estimates:

- ``wheel``: the host's position-based wheel odometry (``Odometry.wheel``);
- ``ekf``: the EKF on wheel velocities and the gyro (``Odometry.ekf_vel``, seed 002's
  scheme; ``docs/odometry.md``);
- ``icp``: ``wcdrive.navigation.icp.IcpOdometry`` on the run's scans, each aligned to the one
  before from the wheel odometry's pose change between their stamps (the guess, and
  the fallback when ICP fails or jumps);
- ``icp_ekf``: the same, the EKF's pose change as the guess and the fallback (seed
  002's part 2: "EKF values as the initial guess");
- ``fused``: ICP fused into an EKF (``Ekf2D``, seed 002's scheme, run again over the
  run's gyro samples and the wheels' speeds from the board's counts): each scan, ICP
  aligns it from the EKF's pose change since the scan before, and the step it finds,
  put on the EKF's pose then, is fused as a pose (x, y, yaw; ``ICP_STEP_VARIANCE``),
  much as robot_localization's ``differential`` mode fuses a second odometry's
  changes; a step ICP fell back on is not fused.

Each is compared at every scan's stamp (the turn's first beam: the scans are
distorted by the motion over their turn, and nothing de-skews them) with the truth
there (interpolated between control ticks), the odometries placed at the start pose
(``wcdrive.sim.result.placed``). ``Errors``: the final position error, the RMS position
error over the run, the final heading error, and for ICP the scans it fell back on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wcdrive.host.odometry import GyroIntegrator
from wcdrive.navigation.ekf import Ekf2D, EkfConfig
from wcdrive.navigation.icp import IcpOdometry, Pose2D, compose, relative
from wcdrive.plant.params import ChairParams
from wcdrive.sim.result import SimResult, placed

#: The estimates compared, in the table's order, with their labels.
ESTIMATES = {"wheel": "wheel odometry", "ekf": "EKF (wheel velocities + gyro)",
             "icp": "ICP (wheel guess)", "icp_ekf": "ICP + EKF (EKF guess)",
             "fused": "EKF fusing ICP"}
#: The variance of each ICP step fused into the EKF (``fused``): x, y (m^2), yaw (rad^2):
#: 1 cm and 0.3 deg of spread, chosen, not measured.
ICP_STEP_VARIANCE = (1e-4, 1e-4, 2.5e-5)


@dataclass(frozen=True)
class Errors:
    """One estimate against the truth at the scans' stamps (m, degrees); ``fallbacks``
    the scans ICP left to its guess (None for the others)."""

    final_m: float
    rms_m: float
    heading_deg: float
    fallbacks: int | None = None
    scans: int = 0


def _at(times: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """``poses`` (n, 3) at ``times``, linear between the rows (the heading unwrapped)."""
    heading = np.unwrap(poses[:, 2])
    return np.column_stack([np.interp(times, t, poses[:, 0]), np.interp(times, t, poses[:, 1]),
                            np.interp(times, t, heading)])


def _icp(result: SimResult, guesses: np.ndarray, **options: object) -> tuple[np.ndarray, int]:
    """ICP odometry over the run's scans, each step's guess (and fallback) the change
    of ``guesses`` (odometry poses (n, 3) at the scans' stamps) since the scan before."""
    assert result.lidar is not None
    options = dict(options)
    mount = options.pop("mount", result.lidar.lidar.mount)    # the scans' mount unless told
    odom = IcpOdometry(mount, **options)                      # type: ignore[arg-type]
    out = []
    for k, scan in enumerate(result.lidar.scans):
        guess: Pose2D = (0.0, 0.0, 0.0) if k == 0 else relative(tuple(guesses[k - 1]), tuple(guesses[k]))
        out.append(odom.update(scan, guess))
    return np.array(out), odom.fallbacks


def estimates(result: SimResult, only: tuple[str, ...] = tuple(ESTIMATES), **icp_options: object
              ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, int]]:
    """The scans' stamps, the poses at them of each estimate in ``only`` (odometry
    frame, from 0, 0, 0) and ICP's fallbacks. Needs a run with a lidar and the EKF
    (``run(..., ekf=True)``); ``icp_options`` go to ``IcpOdometry``."""
    if result.lidar is None or not result.lidar.scans:
        raise ValueError("the run has no scans: a scenario with a [lidar] table")
    if result.odometry.ekf_vel is None:
        raise ValueError("the run has no EKF: run(..., ekf=True)")
    t = result.board.tick_time
    stamps = np.array([s.stamp for s in result.lidar.scans])
    wheel = _at(stamps, t, result.odometry.wheel)
    ekf = _at(stamps, t, result.odometry.ekf_vel)
    poses, fallbacks = {"wheel": wheel, "ekf": ekf}, {}
    for name, guesses in (("icp", wheel), ("icp_ekf", ekf)):
        if name in only:
            poses[name], fallbacks[name] = _icp(result, guesses, **icp_options)
    if "fused" in only:
        poses["fused"], fallbacks["fused"] = _fused(result, **icp_options)
    return stamps, {k: v for k, v in poses.items() if k in only}, fallbacks


def _fused(result: SimResult, **options: object) -> tuple[np.ndarray, int]:
    """The ``fused`` estimate (module docstring) at the scans' stamps, and the steps
    ICP fell back on; the wheels' figures are ``ChairParams``' defaults."""
    assert result.lidar is not None
    params = ChairParams()
    options = dict(options)
    mount = options.pop("mount", result.lidar.lidar.mount)
    odom = IcpOdometry(mount, **options)                      # type: ignore[arg-type]
    ekf = Ekf2D(EkfConfig.wheel_velocities())
    gyro = GyroIntegrator()
    board = result.board
    per_count = 2.0 * math.pi / params.counts_per_rev * params.wheel_radius
    scans = result.lidar.scans
    # every source in time order: gyro samples (0), control ticks (1), scans (2)
    events = sorted([(float(t), 0, i) for i, t in enumerate(result.odometry.gyro_time)]
                    + [(float(t), 1, i) for i, t in enumerate(board.tick_time) if i > 0]
                    + [(s.stamp, 2, i) for i, s in enumerate(scans)])
    out: list[Pose2D] = []
    last: Pose2D = (0.0, 0.0, 0.0)
    for t, kind, i in events:
        if kind == 0:
            rate = float(result.odometry.gyro_rate[i])
            gyro.add(t, rate)
            ekf.imu(t, gyro.heading, rate)
        elif kind == 1:
            dt = float(board.tick_time[i] - board.tick_time[i - 1])
            if dt <= 0:
                continue
            left = -float(board.counts[i, 0] - board.counts[i - 1, 0]) * per_count
            right = float(board.counts[i, 1] - board.counts[i - 1, 1]) * per_count
            ekf.odometry(t, 0.0, 0.0, 0.0, 0.5 * (left + right) / dt, (right - left) / params.wheelbase / dt)
        else:
            ekf.predict(t)
            prior = ekf.pose
            before, start = odom.fallbacks, odom.pose
            odom.update(scans[i], (0.0, 0.0, 0.0) if i == 0 else relative(last, prior))
            if i > 0 and odom.fallbacks == before:
                x, y, yaw = compose(last, relative(start, odom.pose))
                ekf.pose_measurement(t, x, y, yaw, ICP_STEP_VARIANCE)
            last = ekf.pose
            out.append(last)
    return np.array(out), odom.fallbacks


def compare(result: SimResult, only: tuple[str, ...] = tuple(ESTIMATES), **icp_options: object
            ) -> dict[str, Errors]:
    """The errors against the truth of each estimate in ``only`` (module docstring)."""
    stamps, poses, fallbacks = estimates(result, only, **icp_options)
    truth = _at(stamps, result.board.tick_time, result.truth.pose)
    start = result.world.start if result.world is not None else (0.0, 0.0, 0.0)
    out = {}
    for name, est in poses.items():
        p = placed(start, est)
        d = np.hypot(p[:, 0] - truth[:, 0], p[:, 1] - truth[:, 1])
        heading = math.degrees(math.remainder(float(p[-1, 2] - truth[-1, 2]), 2 * math.pi))
        out[name] = Errors(float(d[-1]), float(np.sqrt(np.mean(d ** 2))), heading, fallbacks.get(name),
                           len(stamps))
    return out
