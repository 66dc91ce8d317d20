"""The seeds' EKF (``wcdrive.navigation.ekf``): robot_localization's 2D mode on filterpy,
fusing the states seed 000's ekf.yaml names, and what it does on a slipping wheel."""

from __future__ import annotations

import json
import math

import pytest

from wcdrive.navigation.ekf import VX, VYAW, YAW, Ekf2D, EkfConfig, X, Y, _selected
from wcdrive.sim import report, runner, scenario


def test_the_seed_000_configuration_fuses_what_ekf_yaml_says() -> None:
    config = EkfConfig()
    assert _selected(config.odom0_config) == [X, Y, VX]            # x, y, vx from the wheels
    assert _selected(config.imu0_config) == [YAW, VYAW]            # yaw, vyaw from the IMU
    assert _selected(EkfConfig.wheel_velocities().odom0_config) == [VX, 4]   # vx, vy


def test_a_turn_at_constant_speed_is_tracked() -> None:
    """Wheels at 0.5 m/s and a gyro at 0.2 rad/s, both exact: the EKF's pose is the
    arc's (the omnidirectional model's Jacobian and the yaw wrap are right), within
    the bias of robot_localization's Euler steps (half a step's turn of heading)."""
    ekf = Ekf2D(EkfConfig.wheel_velocities())
    v, w = 0.5, 0.2
    for k in range(0, 4001):                        # 40 s at 100 Hz: past a full turn
        t = 0.01 * k
        ekf.imu(t, math.remainder(w * t, 2 * math.pi), w)
        ekf.odometry(t, 0.0, 0.0, 0.0, v, w)
    t = 40.0
    x, y, yaw = ekf.pose
    assert x == pytest.approx(v / w * math.sin(w * t), abs=0.05)
    assert y == pytest.approx(v / w * (1 - math.cos(w * t)), abs=0.05)
    assert yaw == pytest.approx(math.remainder(w * t, 2 * math.pi), abs=1e-3)
    assert ekf.twist == pytest.approx((v, w), abs=1e-3)


def test_the_ekf_beats_wheel_odometry_on_slip_turn() -> None:
    """The left wheel slips: wheel-only odometry ends 1.6 m off. Fusing the wheels'
    velocities with the gyro's yaw ends within 0.2 m; seed 000's configuration, which
    also fuses the wheels' x and y, follows their error (docs/odometry.md)."""
    result = runner.run(scenario.load("slip_turn"), ekf=True)
    m = result.metrics()
    wheel = m["odom_wheel_position_error_m"]
    assert isinstance(wheel, float) and wheel > 1.0
    assert m["odom_ekf_vel_position_error_m"] < 0.2 < 0.15 * wheel
    assert m["odom_ekf_position_error_m"] == pytest.approx(wheel, rel=0.1)
    assert abs(m["odom_ekf_heading_error_deg"]) < 0.5 < abs(m["odom_wheel_heading_error_deg"])
    data = json.loads(report.to_json([result]))[0]
    assert "odom_ekf_position_error_m" in data and "odom_ekf_vel_position_error_m" in data
    assert "odom_ekf_x" not in runner.run(scenario.load("slip_turn")).metrics()   # only when asked
