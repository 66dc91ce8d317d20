"""The drive limits (docs/safety.md, "Drive limits"): a drive profile's top speeds
forward and back, ramps, turn rate, turn acceleration and turn at full speed, as
runtime parameters that cap what the host may ask. Held here on the port to figures
worked by hand, and at their defaults to the ramp there was before them;
tests/firmware/test_drive_limits_lockstep.py runs them on both backends."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wcdrive.avr.f32 import f32, mul
from wcdrive.firmware import constants as C
from wcdrive.firmware.drive import drive_caps, ramp_setpoints, ramp_toward, wheel_rate
from wcdrive.firmware.state import FirmwareState

R, B = 0.1524, 0.57
wheel = st.floats(-C.MAX_WHEEL_SPEED, C.MAX_WHEEL_SPEED, width=32)


@given(wheel, wheel, wheel, wheel, st.sampled_from([0, 1]), st.floats(0.5, 7.0, width=32))
def test_at_the_defaults_nothing_is_capped_and_the_ramp_is_max_accel(goal_l, goal_r, sp_l, sp_r, emergency,
                                                                     max_accel) -> None:
    """Any goals the wheels can take pass the default limits as they are, and the
    setpoints step exactly as the ramp before the limits did (max_accel, or estop_decel
    on the emergency ramp), bit for bit."""
    s = FirmwareState(setpointL=sp_l, setpointR=sp_r, emergencyStop=emergency, maxAccel=max_accel)
    assert drive_caps(s, goal_l, goal_r) == (goal_l, goal_r)
    step = mul(s.estopDecel if emergency else s.maxAccel, f32(0.05))
    want = (ramp_toward(sp_l, goal_l, step), ramp_toward(sp_r, goal_r, step))
    ramp_setpoints(s, goal_l, goal_r, f32(0.05))
    assert (s.setpointL, s.setpointR) == want


def test_the_top_speeds_forward_and_back() -> None:
    """fwd_speed 1.0 m/s: 10 rad/s on both wheels (1.52 m/s) becomes 1.0 / 0.1524 =
    6.562 rad/s; rev_speed 0.5 m/s: -10 becomes -3.281; a turn rides along unchanged."""
    s = FirmwareState(fwdSpeed=f32(1.0), revSpeed=f32(0.5))
    assert drive_caps(s, 10.0, 10.0) == pytest.approx((1.0 / R, 1.0 / R), rel=1e-6)
    assert drive_caps(s, -10.0, -10.0) == pytest.approx((-0.5 / R, -0.5 / R), rel=1e-6)
    left, right = drive_caps(s, 9.0, 11.0)          # 1.52 m/s turning at 0.535 rad/s
    assert (left + right) / 2 * R == pytest.approx(1.0, rel=1e-6)
    assert (right - left) * R / B == pytest.approx(2.0 * R / B, rel=1e-6)
    assert drive_caps(s, 3.0, 4.0) == (3.0, 4.0)     # within both: as it was


def test_the_turn_rate_and_its_cut_at_speed() -> None:
    """turn_speed 1.0 rad/s: a spin at 5 rad/s a wheel (2.67 rad/s) becomes +-1 x 0.285
    / 0.1524 = 1.870 rad/s a wheel. With fwd_speed 2.0 and turn_at_speed 0.5 the turn
    limit at 2.0 m/s is half, 0.5 rad/s; at 1.0 m/s, 0.75 rad/s."""
    spin = FirmwareState(turnSpeed=f32(1.0))
    assert drive_caps(spin, -5.0, 5.0) == pytest.approx((-0.285 / R, 0.285 / R), rel=1e-5)
    s = FirmwareState(fwdSpeed=f32(2.0), turnSpeed=f32(1.0), turnAtSpeed=f32(0.5))
    for speed, cap in ((2.0, 0.5), (1.0, 0.75)):
        v = speed / R
        left, right = drive_caps(s, v - 3.0, v + 3.0)
        assert (right - left) * R / B == pytest.approx(cap, rel=1e-5), speed
        assert (left + right) / 2 * R == pytest.approx(speed, rel=1e-5)


def test_the_ramps_speeding_up_and_slowing_down() -> None:
    """drive_accel 0.5 m/s^2 is 3.281 rad/s^2 a wheel; drive_decel 1.0 m/s^2 would be
    6.562, past max_accel's 5: 5. Away from zero is speeding up, toward it slowing."""
    s = FirmwareState(driveAccel=f32(0.5), driveDecel=f32(1.0))
    assert wheel_rate(s, 0.0, 4.0) == pytest.approx(0.5 / R, rel=1e-6)
    assert wheel_rate(s, -1.0, -4.0) == pytest.approx(0.5 / R, rel=1e-6)
    assert wheel_rate(s, 4.0, 1.0) == wheel_rate(s, 4.0, -4.0) == C.MAX_ACCEL
    ramp_setpoints(s, 4.0, 4.0, f32(0.05))
    assert s.setpointL == s.setpointR == pytest.approx(0.05 * 0.5 / R, rel=1e-6)


def test_the_turn_rate_changes_no_faster_than_turn_accel() -> None:
    """turn_accel 1 rad/s^2: from straight at 2 rad/s to a turn, the wheels' half
    difference moves 1 x 0.285 / 0.1524 x 0.05 = 0.0935 rad/s a tick, their mean as
    the per-wheel ramp takes it."""
    s = FirmwareState(setpointL=2.0, setpointR=2.0, turnAccel=f32(1.0))
    ramp_setpoints(s, 1.0, 3.0, f32(0.05))
    assert (s.setpointR - s.setpointL) / 2 == pytest.approx(0.285 / R * 0.05, rel=1e-5)
    assert (s.setpointR + s.setpointL) / 2 == pytest.approx(2.0, abs=1e-6)
