"""The speed limits of ROS 2 Jazzy's ``diff_drive_controller``, applied as it applies
them. Pure: no I/O.

``RateLimiter`` is ``control_toolbox::RateLimiter<double>`` (control_toolbox, jazzy
branch, ``include/control_toolbox/rate_limiter.hpp``): ``limit(v, v0, v1, dt)`` limits
the second derivative (jerk: only while it grows the acceleration, ``(dv - dv0)·(v - v0)
> 0``), then the first (acceleration: ``v0 + clamp(v - v0, dv_min, dv_max)``, the
bounds chosen by the sign of ``v0``: forward, reverse, or from rest), then the value
(velocity: ``clamp(v, min, max)``). A limit that is NaN is off; a NaN minimum is
``-maximum``; the asymmetric first-derivative bounds default to the symmetric ones; a
minimum above its maximum is refused (``ValueError``, as ``std::invalid_argument``).

``SpeedLimiter`` is ``diff_drive_controller::SpeedLimiter`` (ros2_controllers, jazzy
branch, ``speed_limiter.hpp``): min/max velocity, ``max_acceleration_reverse``
(≤ 0), ``max_acceleration`` (≥ 0), ``max_deceleration`` (≤ 0),
``max_deceleration_reverse`` (≥ 0), min/max jerk, in that order onto the rate limiter.
``AxisLimits`` holds one axis's parameters (``linear.x.*`` or ``angular.z.*``) with the
deprecated ``has_*_limits`` flags, which, when false, turn their limits off
(``DiffDriveController::on_configure``).

``CommandLimiter`` is the controller's update step (``update_and_write_commands``):
each period the reference ``(linear, angular)`` is limited against the last two limited
commands (both zero at the start and after ``reset``), and the result becomes the
newest of the two. ``counts`` tallies, per axis and stage, the steps in which a limit
was active ("linear.x velocity", "angular.z acceleration", ...).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

__all__ = ["AxisLimits", "CommandLimiter", "RateLimiter", "SpeedLimiter"]

NAN = math.nan


def _clamp(value: float, low: float, high: float) -> float:
    """``std::clamp``."""
    return low if value < low else high if high < value else value


class RateLimiter:
    """``control_toolbox::RateLimiter<double>`` (module docstring). ``limit`` returns the
    limited value; ``active`` then names the stages that were limiting ("jerk",
    "acceleration", "velocity")."""

    def __init__(self, min_value: float = NAN, max_value: float = NAN,
                 min_first_derivative_neg: float = NAN, max_first_derivative_pos: float = NAN,
                 min_first_derivative_pos: float = NAN, max_first_derivative_neg: float = NAN,
                 min_second_derivative: float = NAN, max_second_derivative: float = NAN) -> None:
        self.has_value_limits = not math.isnan(max_value)
        if math.isnan(min_value):
            min_value = -max_value
        if self.has_value_limits and min_value > max_value:
            raise ValueError("Invalid value limits")
        self.has_first_derivative_limits = not math.isnan(max_first_derivative_pos)
        if math.isnan(min_first_derivative_neg):
            min_first_derivative_neg = -max_first_derivative_pos
        if self.has_first_derivative_limits and min_first_derivative_neg > max_first_derivative_pos:
            raise ValueError("Invalid first derivative limits")
        if self.has_first_derivative_limits:
            if math.isnan(max_first_derivative_neg):
                max_first_derivative_neg = max_first_derivative_pos
            if math.isnan(min_first_derivative_pos):
                min_first_derivative_pos = min_first_derivative_neg
            if min_first_derivative_pos > max_first_derivative_neg:
                raise ValueError("Invalid first derivative limits")
        self.has_second_derivative_limits = not math.isnan(max_second_derivative)
        if math.isnan(min_second_derivative):
            min_second_derivative = -max_second_derivative
        if self.has_second_derivative_limits and min_second_derivative > max_second_derivative:
            raise ValueError("Invalid second derivative limits")
        self.min_value, self.max_value = min_value, max_value
        self.min_first_derivative_neg = min_first_derivative_neg
        self.max_first_derivative_pos = max_first_derivative_pos
        self.min_first_derivative_pos = min_first_derivative_pos
        self.max_first_derivative_neg = max_first_derivative_neg
        self.min_second_derivative, self.max_second_derivative = min_second_derivative, max_second_derivative
        self.active: list[str] = []

    @property
    def limits_anything(self) -> bool:
        """Whether any limit is on."""
        return self.has_value_limits or self.has_first_derivative_limits or self.has_second_derivative_limits

    def limit(self, v: float, v0: float, v1: float, dt: float) -> float:
        """``v`` limited after ``v0`` and, before it, ``v1``, ``dt`` s apart."""
        self.active = []
        v = self.limit_second_derivative(v, v0, v1, dt)
        v = self.limit_first_derivative(v, v0, dt)
        return self.limit_value(v)

    def limit_value(self, v: float) -> float:
        """``v`` within the value limits."""
        if self.has_value_limits:
            limited = _clamp(v, self.min_value, self.max_value)
            if limited != v:
                self.active.append("velocity")
            v = limited
        return v

    def limit_first_derivative(self, v: float, v0: float, dt: float) -> float:
        """``v`` within the first-derivative limits after ``v0``."""
        if self.has_first_derivative_limits:
            if v0 > 0.0:
                dv_max, dv_min = self.max_first_derivative_pos * dt, self.min_first_derivative_pos * dt
            elif v0 < 0.0:
                dv_min, dv_max = self.min_first_derivative_neg * dt, self.max_first_derivative_neg * dt
            else:
                dv_min, dv_max = self.min_first_derivative_neg * dt, self.max_first_derivative_pos * dt
            dv = _clamp(v - v0, dv_min, dv_max)
            if dv != v - v0:
                self.active.append("acceleration")
            v = v0 + dv
        return v

    def limit_second_derivative(self, v: float, v0: float, v1: float, dt: float) -> float:
        """``v`` within the second-derivative limits after ``v0`` and ``v1`` (only while
        the acceleration grows)."""
        if self.has_second_derivative_limits:
            dv, dv0 = v - v0, v0 - v1
            if (dv - dv0) * (v - v0) > 0:
                dt2 = dt * dt
                da = _clamp(dv - dv0, self.min_second_derivative * dt2, self.max_second_derivative * dt2)
                if da != dv - dv0:
                    self.active.append("jerk")
                v = v0 + dv0 + da
        return v


class SpeedLimiter(RateLimiter):
    """``diff_drive_controller::SpeedLimiter`` (module docstring)."""

    def __init__(self, min_velocity: float = NAN, max_velocity: float = NAN,
                 max_acceleration_reverse: float = NAN, max_acceleration: float = NAN,
                 max_deceleration: float = NAN, max_deceleration_reverse: float = NAN,
                 min_jerk: float = NAN, max_jerk: float = NAN) -> None:
        super().__init__(min_velocity, max_velocity, max_acceleration_reverse, max_acceleration,
                         max_deceleration, max_deceleration_reverse, min_jerk, max_jerk)


@dataclass(frozen=True)
class AxisLimits:
    """One axis's limits as the controller's parameters name them (``linear.x.*``,
    ``angular.z.*``; NaN: off). ``min_acceleration`` is accepted and, as in Jazzy's
    controller, not used (deprecated for ``max_deceleration``)."""

    max_velocity: float = NAN
    min_velocity: float = NAN
    max_acceleration: float = NAN
    max_deceleration: float = NAN
    max_acceleration_reverse: float = NAN
    max_deceleration_reverse: float = NAN
    max_jerk: float = NAN
    min_jerk: float = NAN
    min_acceleration: float = NAN
    has_velocity_limits: bool = True
    has_acceleration_limits: bool = True
    has_jerk_limits: bool = True

    def limiter(self) -> SpeedLimiter:
        """The axis's ``SpeedLimiter`` (``ValueError`` for limits the controller refuses)."""
        v_min, v_max = (self.min_velocity, self.max_velocity) if self.has_velocity_limits else (NAN, NAN)
        if self.has_acceleration_limits:
            accel = (self.max_acceleration_reverse, self.max_acceleration, self.max_deceleration,
                     self.max_deceleration_reverse)
        else:
            accel = (NAN, NAN, NAN, NAN)
        j_min, j_max = (self.min_jerk, self.max_jerk) if self.has_jerk_limits else (NAN, NAN)
        return SpeedLimiter(v_min, v_max, *accel, j_min, j_max)

    def describe(self) -> dict[str, float]:
        """The limits in force (name -> value; off ones left out)."""
        names = ["max_velocity", "min_velocity", "max_acceleration", "max_deceleration",
                 "max_acceleration_reverse", "max_deceleration_reverse", "max_jerk", "min_jerk"]
        groups = {"velocity": self.has_velocity_limits, "accel": self.has_acceleration_limits,
                  "decel": self.has_acceleration_limits, "jerk": self.has_jerk_limits}
        out = {}
        for name in names:
            group = next(g for g in groups if g in name)
            value = getattr(self, name)
            if groups[group] and not math.isnan(value):
                out[name] = value
        return out


class CommandLimiter:
    """The controller's limiting step for ``(linear, angular)`` commands (module
    docstring). ``step(reference, dt)`` gives the command to send; ``counts`` the
    tallies; ``last`` the newest limited command."""

    AXES = ("linear.x", "angular.z")

    def __init__(self, linear: AxisLimits | None = None, angular: AxisLimits | None = None) -> None:
        self.linear, self.angular = linear or AxisLimits(), angular or AxisLimits()
        self._limiters = (self.linear.limiter(), self.angular.limiter())
        self.counts: Counter[str] = Counter()
        self.reset()

    @property
    def active(self) -> bool:
        """Whether any limit is on."""
        return any(limiter.limits_anything for limiter in self._limiters)

    def reset(self) -> None:
        """Forgets the last two commands (both zero again: ``reset_buffers``)."""
        self._previous = [(0.0, 0.0), (0.0, 0.0)]            # second to last, last

    @property
    def last(self) -> tuple[float, float]:
        """The newest limited command."""
        return self._previous[1]

    def step(self, reference: tuple[float, float], dt: float) -> tuple[float, float]:
        """``reference`` limited for a period of ``dt`` s; it becomes the newest command."""
        (linear1, angular1), (linear0, angular0) = self._previous
        out = []
        for axis, limiter, v, v0, v1 in zip(self.AXES, self._limiters, reference, (linear0, angular0),
                                            (linear1, angular1), strict=True):
            limited = limiter.limit(float(v), v0, v1, dt)
            for stage in limiter.active:
                self.counts[f"{axis} {stage}"] += 1
            out.append(limited)
        command = (out[0], out[1])
        self._previous = [self._previous[1], command]
        return command

    @property
    def limited(self) -> int:
        """How many times a limit was active (each step, axis and stage counted once)."""
        return sum(self.counts.values())
