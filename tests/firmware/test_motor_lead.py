"""The motor rule (``noEffect``, ``effortLeads``, ``atLimit``) and the stall rule
(``checkWheel``) on the port, tick by tick. The motor rule: effort without progress is a
dead motor only while the wheel trails the other one its way (or stands, when the other
turns against it), and only while its effort (duty less back-EMF, up to the current
limit) leads the other wheel's. A dead motor's wheel is only dragged along, so it never
leads the wheel that drags it; a wheel that leads is pulled by its own motor, at its
current limit on a grade; two wheels whose efforts rise together carry the chair's load
(the closed-loop cases: tests/sim/test_grade_false_alarms.py and the envelope property).

Each case feeds ``no_effect`` the duty rising one step a tick toward a steady setpoint
with the speed flat and short of it, as the current limit gives, and counts the ticks
to its verdict.
"""

from __future__ import annotations

import pytest

from wcdrive.firmware import constants as C
from wcdrive.firmware.control import (
    WHEEL_NO_EFFECT,
    WHEEL_OK,
    WHEEL_REVERSED,
    WHEEL_STALLED,
    at_limit,
    check_wheel,
    compute_pid,
    overruns,
    stalling,
    stalls_loaded,
)
from wcdrive.firmware.motor_rule import effort_leads, effort_of, no_effect

SETPOINT = 2.85   # rad/s toward which the duty rises


def _ticks_to_trip(measured: float, other: float, setpoint: float = SETPOINT, ticks: int = 40,
                   other_overruns: bool = False) -> int | None:
    """The tick at which the rule trips, the duty rising 2 a tick from 80, or None. The
    other wheel is driven on beyond its setpoint or not."""
    direction = C.HIGH if setpoint > 0.0 else C.LOW
    effort = (0, 0.0, 0.0, 0)
    for k in range(ticks):
        tripped, effort = no_effect(80 + 2 * k, direction, setpoint, measured, other, 80,
                                    other_overruns, effort)
        if tripped:
            return k
    return None


@pytest.mark.parametrize(("measured", "other"), [(1.45, 1.6), (1.45, 1.45), (1.4, 1.0), (0.4, 0.0),
                                                 (0.4, -0.5)])
def test_a_wheel_that_trails_the_other_is_a_dead_motor(measured: float, other: float) -> None:
    """Short of its setpoint, behind (or no further ahead than FAULT_EFFORT_LEAD of) the
    other wheel its way, or of standing when the other one turns against it: tripped
    once the duty rose FAULT_EFFORT_PWM and the effort count ran."""
    assert measured < max(other, 0.0) + C.FAULT_EFFORT_LEAD
    assert _ticks_to_trip(measured, other) is not None


def test_a_wheel_standing_while_the_other_turns_against_it_is_a_dead_motor() -> None:
    """A spin about a dead wheel: the other drives back at 2 rad/s, this one stands.
    Measured against standing, not against the other's speed, it trails."""
    assert _ticks_to_trip(0.05, -2.0) is not None


@pytest.mark.parametrize("other", [0.9, 0.5, 0.05, -1.0])
def test_a_wheel_that_leads_the_other_is_pulled_by_its_motor(other: float) -> None:
    """At 1.45 rad/s, more than FAULT_EFFORT_LEAD ahead of the other wheel its way (or of
    standing): its motor works, whatever the duty does."""
    assert 1.45 >= max(other, 0.0) + C.FAULT_EFFORT_LEAD
    assert _ticks_to_trip(1.45, other) is None


def test_the_lead_is_taken_the_way_of_the_setpoint() -> None:
    """Driven backwards the same: leading the other wheel backwards is pulling."""
    assert _ticks_to_trip(-1.45, -0.05, setpoint=-SETPOINT) is None
    assert _ticks_to_trip(-1.45, -1.6, setpoint=-SETPOINT) is not None


def test_a_duty_pinned_at_full_counts_only_with_the_partner_near_full_too() -> None:
    """At full duty the duty can rise no more: with the other wheel's duty within
    FAULT_EFFORT_PWM of it (the chair at its top speed) that is effort enough; with the
    other far below (the outer wheel of a turn asking more than the motor gives), not."""
    def trips(other_pwm: int) -> bool:
        effort = (0, 0.0, 0.0, 0)
        for _ in range(10):
            tripped, effort = no_effect(255, C.HIGH, 9.84, 7.0, 8.4, other_pwm, False, effort)
            if tripped:
                return True
        return False
    assert trips(255 - C.FAULT_EFFORT_PWM)
    assert not trips(254 - C.FAULT_EFFORT_PWM)


def test_effort_is_the_duty_less_the_back_emf_up_to_the_current_limit() -> None:
    assert effort_of(50, C.HIGH, 3.0, 2.0) == pytest.approx(50 - 2.0 * C.FAULT_EFFORT_EMF, rel=1e-6)
    assert effort_of(255, C.HIGH, 3.0, 2.0) == C.FAULT_EFFORT_MAX          # past the limit: no more torque
    assert effort_of(30, C.LOW, 3.0, 2.0) < 0.0                           # braking against the setpoint
    assert effort_of(50, C.LOW, -3.0, -2.0) == effort_of(50, C.HIGH, 3.0, 2.0)     # backwards the same
    assert effort_of(200, C.HIGH, 0.0, 2.0) == 0.0                        # no setpoint, no effort


@pytest.mark.parametrize(("this", "other", "expected"), [
    ((72, 2.37, 3.28), (56, 2.85, 3.28), True),       # a dead left motor on the level, 1 s on
    ((74, 2.32, 3.28), (73, 2.28, 3.28), False),      # both wheels onto a 1:12 ramp at 0.5 m/s
    ((136, 2.57, 3.28), (128, 2.80, 3.28), False),    # both at the current limit, a 0.23 rad/s yaw
    ((255, 6.8, 9.84), (250, 8.4, 9.84), True),       # both at the limit, a dead wheel 1.6 behind
    ((155, 2.9, 3.28), (120, 3.6, 3.28), False),      # both at the limit, the other beyond its setpoint
    ((255, 6.88, 9.97), (238, 6.85, 8.25), False),    # both at the limit, a turn neither wheel gets
    ((255, 6.0, 9.97), (238, 7.1, 8.25), True),       # the same, this wheel 1.1 rad/s behind the other
])
def test_effort_leads_tells_one_motor_from_the_chairs_load(
        this: tuple[int, float, float], other: tuple[int, float, float], expected: bool) -> None:
    """The figures are ticks of the simulated chair (the comment says which)."""
    pwm, measured, setpoint = this
    opwm, omeasured, osetpoint = other
    assert effort_leads(pwm, C.HIGH, setpoint, measured, opwm, C.HIGH, osetpoint, omeasured) is expected


def test_a_partner_braking_short_of_its_setpoint_below_the_limit_excuses_the_lead() -> None:
    """Ticks of the simulated chair. Off a 1:12 band at 2.68 m/s and turning, 149 kg:
    the left wheel brakes (effort -9) while 33 % short of its setpoint, its PID unwinding
    after the descent, and the right one's effort leads it by 16: the chair slowing of its
    own accord. A dead left motor 4.6 s into a 4 degree descent brakes at the current
    limit (-41) while short of its setpoint too: that lead is the right wheel's partner
    carrying a dead wheel, and it counts."""
    assert effort_of(70, C.HIGH, 8.12, 5.45) > -C.FAULT_EFFORT_MAX
    assert not effort_leads(90, C.HIGH, 9.47, 5.74, 70, C.HIGH, 8.12, 5.45)
    assert effort_leads(84, C.HIGH, 6.56, 6.04, 10, C.LOW, 6.56, 5.94)
    # short by less than FAULT_EFFORT_SHORTFALL of its setpoint, or by less than
    # FAULT_EFFORT_OVERRUN (a slow inner wheel): no excuse
    assert effort_leads(90, C.HIGH, 9.47, 5.74, 70, C.HIGH, 6.5, 5.45)
    assert effort_leads(40, C.HIGH, 2.0, 1.2, 12, C.HIGH, 1.2, 0.9)
    assert not effort_leads(40, C.HIGH, 2.0, 1.2, 12, C.HIGH, 1.5, 0.9)


def test_the_pid_anti_windup_never_turns_the_integral_against_the_saturation() -> None:
    """A P term beyond the clamp on its own (a low ki, a big error) back-calculates
    the integral to 0, not past it: the wheel is not driven backward once the error
    falls (a climb at 2.44 m/s with ki 0.07 rolled back down a 4 degree grade)."""
    out, integral = compute_pid(20.0, 0.0, 0.0, 0.0, 9.63, 0.07, 0.044, 0.05)
    assert out == C.PID_OUT_MAX and integral == 0.0
    out, integral = compute_pid(-20.0, 0.0, 0.0, 0.0, 9.63, 0.07, 0.044, 0.05)
    assert out == -C.PID_OUT_MAX and integral == 0.0
    # the back-calculation still trims an integral wound up the saturation's way
    out, integral = compute_pid(3.0, 0.0, 5000.0, 0.0, 9.63, 0.07, 0.044, 0.05)
    assert out == C.PID_OUT_MAX and 0.0 < integral < 5000.0
    assert 9.63 * 3.0 + 0.07 * integral == pytest.approx(C.PID_OUT_MAX, rel=1e-4)


def test_no_effect_without_a_lead_is_the_limit_only_once_the_wheel_stalls() -> None:
    """A load both wheels share is the chair's limit (STALLED_ON_GRADE) only below
    GRADE_STALL of the setpoint: within the rated grade a chair slows and climbs on."""
    assert stalling(3.28, 0.8 * C.GRADE_STALL * 3.28) and not stalling(3.28, 1.2 * C.GRADE_STALL * 3.28)
    assert stalling(-3.28, 0.5) and stalling(3.28, -0.5)                  # against the setpoint
    assert at_limit(WHEEL_NO_EFFECT, False, True, False, 0, 0, 1)
    assert not at_limit(WHEEL_NO_EFFECT, False, False, True, 0, 0, 1)     # not stalling: climbs on
    assert not at_limit(WHEEL_NO_EFFECT, True, True, True, 0, 0, 1)       # it leads: its motor
    assert not at_limit(WHEEL_NO_EFFECT, False, True, False, 0, 0, 0)     # the other shows nothing
    assert at_limit(WHEEL_REVERSED, False, False, False, 1, 0, 0)
    assert not at_limit(WHEEL_OK, False, True, True, 1, 1, 1)


def test_a_wheel_whose_partner_is_driven_beyond_its_setpoint_is_not_counted() -> None:
    """The other wheel's own motor driving it on beyond its setpoint: the chair does not
    follow the command, and this wheel's effort goes into turning it."""
    assert _ticks_to_trip(1.45, 1.6, other_overruns=True) is None


@pytest.mark.parametrize(("pwm", "direction", "setpoint", "measured", "expected"), [
    (43, C.HIGH, 2.79, 3.77, True),            # the soak's left wheel: driven on, 1 rad/s beyond
    (43, C.LOW, 2.79, 3.77, False),            # braked beyond it (a slope carries it): no
    (0, C.HIGH, 2.79, 3.77, False),            # coasting: no
    (43, C.HIGH, 2.79, 3.20, False),           # less than FAULT_EFFORT_OVERRUN beyond: no
    (43, C.LOW, -2.79, -3.77, True),           # the same backwards
])
def test_overruns_is_a_wheel_its_own_motor_drives_beyond_its_setpoint(
        pwm: int, direction: int, setpoint: float, measured: float, expected: bool) -> None:
    assert overruns(pwm, direction, setpoint, measured) is expected


def _after_slowing(duties: list[int], held: float = 1.87, setpoint: float = 2.02) -> int | None:
    """A wheel slowed from 3.5 rad/s toward ``setpoint`` on a duty of 17 (a sharp change
    of course: the other wheel ahead at 2.8 rad/s), the duty rising to 34 as it comes
    down to it, then held at ``held`` below it on ``duties``: the tick of ``duties`` at
    which the rule trips, or None."""
    effort = (0, 0.0, 0.0, 0)
    for k, duty in enumerate([17] * 8 + [24, 30, 34]):
        _, effort = no_effect(duty, C.HIGH, setpoint, 3.5 - 0.14 * k, 2.8, duty, False, effort)
    for k, duty in enumerate(duties):
        tripped, effort = no_effect(duty, C.HIGH, setpoint, held, 2.8, duty, False, effort)
        if tripped:
            return k
    return None


def test_a_wheel_slowed_to_its_setpoint_is_judged_from_there() -> None:
    """Its duty's return from the low it was slowed on to the duty that holds its
    setpoint (34 to 39) is no effort without progress: the reference starts over while
    the wheel turns faster than its setpoint."""
    assert _after_slowing([35, 37, 38, 39, 39, 39, 39, 39, 38, 39, 40, 39]) is None


def test_a_dead_motor_after_slowing_is_still_found() -> None:
    """The duty rising on from there, without a gain, trips once it rose
    FAULT_EFFORT_PWM above the duty at which the wheel came down to its setpoint."""
    assert _after_slowing(list(range(34, 100, 2))) is not None


def _ticks_to_stall(prev_measured: float, setpoint: float = -0.89, ticks: int = 10, duty: int = 31,
                    other: float = -2.0) -> int | None:
    """The tick count at which a wheel driven at ``duty`` toward ``setpoint``, without a
    count, is a stall, the PID having last run on ``prev_measured``, the other wheel
    turning at ``other``."""
    direction = C.HIGH if setpoint > 0.0 else C.LOW
    stall = 0
    for k in range(ticks):
        verdict, stall, _, _, _ = check_wheel(0, 0, 0, duty, direction, setpoint, 0.0, other, 0, False,
                                              stall, 0, 0, (0, 0.0, 0.0, 0), prev_measured, False)
        if verdict == WHEEL_STALLED:
            return k + 1
    return None


@pytest.mark.parametrize("prev_measured", [0.0, -0.3, -1e-30])
def test_a_wheel_standing_or_turning_its_way_without_counts_stalls_at_once(prev_measured: float) -> None:
    assert _ticks_to_stall(prev_measured) == C.FAULT_STALL_TICKS


@pytest.mark.parametrize("prev_measured", [0.02, 1e-30, 0.7])
def test_a_wheel_turning_round_without_counts_stalls_later(prev_measured: float) -> None:
    """Last seen against its setpoint, however slowly (the filter's residue keeps the
    sign): FAULT_STALL_TICKS_TURNING ticks, and no more."""
    assert C.FAULT_STALL_TICKS < C.FAULT_STALL_TICKS_TURNING
    assert _ticks_to_stall(prev_measured) == C.FAULT_STALL_TICKS_TURNING


def test_a_wheel_standing_beside_a_standing_partner_stalls_only_at_full_torque() -> None:
    """Both wheels slower than FAULT_STANDING_SPEED: on a grade a healthy wheel may stand
    below the motor's full torque, so only FAULT_STALL_PWM_STANDING without a count is a
    stall; a partner that turns, or this wheel having turned, brings back FAULT_STALL_PWM."""
    assert C.FAULT_STALL_PWM < C.FAULT_STALL_PWM_STANDING
    assert _ticks_to_stall(0.0, duty=C.FAULT_STALL_PWM_STANDING - 1, other=0.1) is None
    assert _ticks_to_stall(0.0, duty=C.FAULT_STALL_PWM_STANDING, other=0.1) == C.FAULT_STALL_TICKS
    assert _ticks_to_stall(0.0, duty=C.FAULT_STALL_PWM, other=-2.0) == C.FAULT_STALL_TICKS
    assert _ticks_to_stall(-1.5, duty=C.FAULT_STALL_PWM, other=0.1) == C.FAULT_STALL_TICKS


def test_a_wheel_standing_while_its_partner_rolls_back_stalls_only_at_full_torque() -> None:
    """A partner turning against this wheel's setpoint does not carry the chair its way
    (a turn on a grade pivots back about the standing wheel): as beside a standing
    partner, only FAULT_STALL_PWM_STANDING without a count is a stall."""
    assert _ticks_to_stall(0.0, duty=C.FAULT_STALL_PWM_STANDING - 1, other=2.0) is None
    assert _ticks_to_stall(0.0, duty=C.FAULT_STALL_PWM_STANDING, other=2.0) == C.FAULT_STALL_TICKS
    assert _ticks_to_stall(0.0, setpoint=2.9, duty=C.FAULT_STALL_PWM_STANDING - 1, other=-0.4) is None
    assert _ticks_to_stall(0.0, setpoint=2.9, duty=C.FAULT_STALL_PWM, other=0.4) == C.FAULT_STALL_TICKS


@pytest.mark.parametrize(("setpoint", "prev_measured", "other", "loaded"), [
    (2.9, 0.0, -0.35, True), (2.9, 0.0, -0.25, False), (2.9, 0.0, 0.5, False),
    (2.9, 0.5, -0.5, False), (-1.0, 0.1, 0.4, True), (-1.0, 0.1, -0.4, False)])
def test_a_stall_at_full_torque_with_the_partner_rolling_back_is_the_chairs_limit(
        setpoint: float, prev_measured: float, other: float, loaded: bool) -> None:
    """``stalls_loaded``: the wheel stood and its partner rolls FAULT_STANDING_SPEED or
    more against this wheel's setpoint: the chair pivots back about it."""
    assert stalls_loaded(setpoint, prev_measured, other) is loaded
