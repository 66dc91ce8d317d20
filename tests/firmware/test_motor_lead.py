"""The motor rule (``noEffect``) and the stall rule (``checkWheel``) on the port, tick
by tick. The motor rule: effort without progress is a
dead motor only while the wheel trails the other one its way (or stands, when the other
turns against it). A dead motor's wheel is only dragged along, so it never leads the
wheel that drags it; a wheel that leads is pulled by its own motor, at its current limit
on a grade (the closed-loop case: tests/sim/test_grade_false_alarms.py).

Each case feeds ``no_effect`` the duty rising one step a tick toward a steady setpoint
with the speed flat and short of it, as the current limit gives, and counts the ticks
to its verdict.
"""

from __future__ import annotations

import pytest

from wcdrive.firmware import constants as C
from wcdrive.firmware.control import WHEEL_STALLED, check_wheel, effort_rising, no_effect, overruns

SETPOINT = 2.85   # rad/s toward which the duty rises


def _ticks_to_trip(measured: float, other: float, setpoint: float = SETPOINT, ticks: int = 40,
                   other_rising: bool = False, other_overruns: bool = False) -> int | None:
    """The tick at which the rule trips, the duty rising 2 a tick from 80, or None. The
    other wheel shows effort without progress or not, and is driven on beyond its
    setpoint or not."""
    direction = C.HIGH if setpoint > 0.0 else C.LOW
    effort = (0, 0.0, 0.0, 0)
    for k in range(ticks):
        tripped, effort = no_effect(80 + 2 * k, direction, setpoint, measured, other, other_rising,
                                    other_overruns, effort)
        if tripped:
            return k
    return None


@pytest.mark.parametrize(("measured", "other"), [(1.45, 1.6), (1.45, 1.45), (1.45, 1.0), (0.4, 0.0),
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


def test_a_wheel_whose_partner_strains_too_is_the_chairs_load() -> None:
    """Both wheels' duties up without a gain (the other's by FAULT_EFFORT_PWM): a
    grade or a turn holds the chair back, not one motor. The reference starts over each
    such tick, so the count never runs."""
    assert _ticks_to_trip(1.45, 1.6) is not None
    assert _ticks_to_trip(1.45, 1.6, other_rising=True) is None


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


@pytest.mark.parametrize(("pwm", "measured", "expected"), [
    (75, 3.9, True),       # duty 20 above its lowest (55), at 82 % of its setpoint
    (74, 3.9, False),      # 19 above
    (75, 4.6, False),      # at 96 %: it keeps its setpoint, dragging a dead partner
])
def test_effort_rising_is_effort_without_progress_short_of_the_setpoint(
        pwm: int, measured: float, expected: bool) -> None:
    assert effort_rising(pwm, 55, 4.777, 4.777, measured) is expected


def _after_slowing(duties: list[int], held: float = 1.87, setpoint: float = 2.02) -> int | None:
    """A wheel slowed from 3.5 rad/s toward ``setpoint`` on a duty of 17 (a sharp change
    of course: the other wheel ahead at 2.8 rad/s), the duty rising to 34 as it comes
    down to it, then held at ``held`` below it on ``duties``: the tick of ``duties`` at
    which the rule trips, or None."""
    effort = (0, 0.0, 0.0, 0)
    for k, duty in enumerate([17] * 8 + [24, 30, 34]):
        _, effort = no_effect(duty, C.HIGH, setpoint, 3.5 - 0.14 * k, 2.8, False, False, effort)
    for k, duty in enumerate(duties):
        tripped, effort = no_effect(duty, C.HIGH, setpoint, held, 2.8, False, False, effort)
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


def _ticks_to_stall(prev_measured: float, setpoint: float = -0.89, ticks: int = 10) -> int | None:
    """The tick count at which a wheel driven at duty 31 toward ``setpoint``, without a
    count, is a stall, the PID having last run on ``prev_measured``."""
    direction = C.HIGH if setpoint > 0.0 else C.LOW
    stall = 0
    for k in range(ticks):
        verdict, stall, _, _, _ = check_wheel(0, 0, 0, 31, direction, setpoint, 0.0, 0.0, False, False,
                                              stall, 0, 0, (0, 0.0, 0.0, 0), prev_measured)
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
