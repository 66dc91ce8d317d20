"""diff_drive_controller's limits as Jazzy applies them (``wcdrive.ros2.limits``):
control_toolbox's ``RateLimiter`` held to control_toolbox's own test vectors
(``control_toolbox/test/rate_limiter.cpp``, jazzy), a ramp worked by hand, and the
controller's update step with its counts."""

from __future__ import annotations

import math

import pytest

from wcdrive.ros2.limits import AxisLimits, CommandLimiter, RateLimiter, SpeedLimiter

NAN = math.nan


def test_control_toolbox_value_and_first_derivative_vectors() -> None:
    """``testValueLimits``, ``testFirstDerivativeLimits``: (-0.5, 1.0) m/s, (-0.5, 1.0)
    m/s^2, jerk (-2, 5); dt 0.5."""
    limiter = RateLimiter(-0.5, 1.0, -0.5, 1.0, NAN, NAN, -2.0, 5.0)
    assert limiter.limit_value(10.0) == 1.0 and limiter.limit_value(-10.0) == -0.5
    assert limiter.limit(10.0, 0.0, 0.0, 0.5) == 0.5          # the first derivative limits, not the value
    assert limiter.limit(-10.0, 0.0, 0.0, 0.5) == -0.25
    assert limiter.limit_first_derivative(10.0, 0.0, 0.5) == 0.5
    assert limiter.limit_first_derivative(-10.0, 0.0, 0.5) == -0.25


def test_control_toolbox_asymmetric_and_second_derivative_vectors() -> None:
    """``testFirstDerivativeLimitsAsymmetric``, ``testSecondDerivativeLimits``."""
    limiter = RateLimiter(-0.5, 1.0, -0.5, 1.0, -5.0, 10.0, -0.5, 5.0)
    assert limiter.limit_first_derivative(10.0, 5.0, 0.5) == 5.5
    assert limiter.limit_first_derivative(-10.0, 5.0, 0.5) == 2.5
    assert limiter.limit_first_derivative(10.0, -5.0, 0.5) == 0.0
    assert limiter.limit_first_derivative(-10.0, -5.0, 0.5) == -5.25
    jerk = RateLimiter(-0.5, 1.0, -0.5, 1.0, NAN, NAN, -1.0, 1.0)
    assert jerk.limit_second_derivative(10.0, 0.0, 0.0, 0.5) == 0.25
    assert jerk.limit_second_derivative(-10.0, 0.0, 0.0, 0.5) == -0.25
    assert jerk.limit(10.0, 0.0, 0.0, 0.5) == 0.25
    assert jerk.limit(-10.0, 0.0, 0.0, 0.5) == -0.25
    free = RateLimiter()
    assert free.limit(10.0, 0.0, 0.0, 0.5) == 10.0 and not free.limits_anything


@pytest.mark.parametrize("args", [
    (1.0, -1.0, -1.0, 1.0, NAN, NAN, -1.0, 1.0), (-1.0, 1.0, 1.0, -1.0, NAN, NAN, -1.0, 1.0),
    (-1.0, 1.0, 1.0, -1.0, 10.0, -10.0, -1.0, 1.0), (-1.0, 1.0, -1.0, 1.0, NAN, NAN, 1.0, -1.0),
])
def test_control_toolbox_refuses_inverted_limits(args: tuple[float, ...]) -> None:
    """``testWrongParams``: a minimum above its maximum."""
    with pytest.raises(ValueError, match="Invalid"):
        RateLimiter(*args)


def test_a_ramp_worked_by_hand() -> None:
    """``linear.x``: max_velocity 0.4, max_acceleration 0.5, max_deceleration -1.0,
    max_jerk 2.0; steps of dt = 0.1 s toward 1.0 m/s from rest, then toward 0.

    Per step the jerk bound is 2.0 · 0.1² = 0.02 m/s on the change of the speed change
    (``v = v0 + dv0 + da``), the acceleration bound 0.05 m/s up and 0.1 m/s down:

    - step 1: dv0 = 0 -> v = 0.02; step 2: dv0 = 0.02 -> 0.02 + 0.02 + 0.02 = 0.06;
    - step 3: dv0 = 0.04 -> 0.12, a change of 0.06 > 0.05 -> 0.11; from then on 0.05 a
      step: 0.16, 0.21, ..., 0.36;
    - step 9: 0.36 + 0.05 + 0.02 = 0.43 -> 0.41 (acceleration) -> 0.40 (velocity); step 10
      the same: 0.40. The jerk bound is active on all ten steps (the reference is far),
      the acceleration bound from step 3, the velocity bound on steps 9 and 10.
    - toward 0 (the jerk bound applies while the deceleration grows,
      ``(dv - dv0)·(v - v0) > 0``): 0.40 - 0 - 0.02 = 0.38, 0.38 - 0.02 - 0.02 = 0.34,
      0.34 - 0.04 - 0.02 = 0.28, 0.28 - 0.06 - 0.02 = 0.20, 0.20 - 0.08 - 0.02 = 0.10,
      then 0.10 - 0.10 = 0: the reference, reached at the deceleration bound (0.1 a step)."""
    limits = AxisLimits(max_velocity=0.4, max_acceleration=0.5, max_deceleration=-1.0, max_jerk=2.0)
    limiter = CommandLimiter(linear=limits)
    up = [limiter.step((1.0, 0.0), 0.1)[0] for _ in range(10)]
    assert up == pytest.approx([0.02, 0.06, 0.11, 0.16, 0.21, 0.26, 0.31, 0.36, 0.40, 0.40], abs=1e-12)
    assert dict(limiter.counts) == {"linear.x jerk": 10, "linear.x acceleration": 8, "linear.x velocity": 2}
    down = [limiter.step((0.0, 0.0), 0.1)[0] for _ in range(7)]
    assert down == pytest.approx([0.38, 0.34, 0.28, 0.20, 0.10, 0.0, 0.0], abs=1e-12)
    assert limiter.counts["linear.x jerk"] == 10 + 5 and limiter.counts["angular.z velocity"] == 0


def test_the_controllers_deprecated_switches_turn_limits_off() -> None:
    limits = AxisLimits(max_velocity=0.4, max_acceleration=0.5, has_velocity_limits=False)
    assert CommandLimiter(linear=limits).step((1.0, 0.0), 1.0) == (0.5, 0.0)
    assert AxisLimits(max_acceleration=0.5, has_acceleration_limits=False).limiter().limits_anything is False
    assert AxisLimits(max_jerk=1.0, has_jerk_limits=False).limiter().limits_anything is False
    assert AxisLimits(min_acceleration=-0.5).limiter().limits_anything is False   # unused in Jazzy
    assert CommandLimiter().active is False and CommandLimiter(angular=AxisLimits(max_velocity=1.0)).active


def test_asymmetric_reverse_limits_follow_the_controllers_mapping() -> None:
    """SpeedLimiter's order: min/max velocity, max_acceleration_reverse, max_acceleration,
    max_deceleration, max_deceleration_reverse, min/max jerk."""
    limiter = SpeedLimiter(NAN, NAN, -0.2, 0.5, -1.0, 2.0)
    assert limiter.limit(-10.0, 0.0, 0.0, 1.0) == -0.2        # from rest backwards: acceleration reverse
    assert limiter.limit(-10.0, -1.0, -1.0, 1.0) == -1.2      # going backwards, faster
    assert limiter.limit(10.0, -1.0, -1.0, 1.0) == 1.0        # going backwards, braking: 2.0 m/s^2
    assert limiter.limit(-10.0, 1.0, 1.0, 1.0) == 0.0         # going forwards, braking: 1.0 m/s^2


def test_reset_forgets_the_history() -> None:
    limiter = CommandLimiter(linear=AxisLimits(max_acceleration=1.0))
    limiter.step((1.0, 0.0), 0.5)
    assert limiter.last == (0.5, 0.0)
    limiter.reset()
    assert limiter.last == (0.0, 0.0) and limiter.step((1.0, 0.0), 0.5) == (0.5, 0.0)
