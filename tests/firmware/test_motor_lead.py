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
from wcdrive.firmware.control import WHEEL_STALLED, check_wheel, no_effect

SETPOINT = 2.85   # rad/s toward which the duty rises


def _ticks_to_trip(measured: float, other: float, setpoint: float = SETPOINT, ticks: int = 40,
                   other_setpoint: float | None = None, other_rising: bool = False) -> int | None:
    """The tick at which the rule trips, the duty rising 2 a tick from 80, or None. The
    other wheel holds ``other_setpoint`` (its speed by default) and strains or not."""
    direction = C.HIGH if setpoint > 0.0 else C.LOW
    effort = (0, 0.0, 0.0, 0)
    held = other if other_setpoint is None else other_setpoint
    for k in range(ticks):
        tripped, effort = no_effect(80 + 2 * k, direction, setpoint, measured, other, held, other_rising,
                                    effort)
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


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_wheel_whose_partner_runs_beyond_its_setpoint_is_not_counted(sign: float) -> None:
    """The other wheel FAULT_EFFORT_OVERRUN or more beyond its own setpoint its way (the
    chair not following its command: momentum, a slope): not counted; a little less
    beyond it, counted. Either way round."""
    margin = float(C.FAULT_EFFORT_OVERRUN)
    beyond = _ticks_to_trip(sign * 1.45, sign * 1.6, setpoint=sign * SETPOINT,
                            other_setpoint=sign * (1.6 - margin - 0.01))
    within = _ticks_to_trip(sign * 1.45, sign * 1.6, setpoint=sign * SETPOINT,
                            other_setpoint=sign * (1.6 - margin + 0.01))
    assert (beyond, within is not None) == (None, True)


def _after_slowing(duties: list[int], held: float = 1.87, setpoint: float = 2.02) -> int | None:
    """A wheel slowed from 3.5 rad/s toward ``setpoint`` on a duty of 17 (a sharp change
    of course: the other wheel ahead at 2.8 rad/s), the duty rising to 34 as it comes
    down to it, then held at ``held`` below it on ``duties``: the tick of ``duties`` at
    which the rule trips, or None."""
    effort = (0, 0.0, 0.0, 0)
    for k, duty in enumerate([17] * 8 + [24, 30, 34]):
        _, effort = no_effect(duty, C.HIGH, setpoint, 3.5 - 0.14 * k, 2.8, 2.8, False, effort)
    for k, duty in enumerate(duties):
        tripped, effort = no_effect(duty, C.HIGH, setpoint, held, 2.8, 2.8, False, effort)
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
        verdict, stall, _, _, _ = check_wheel(0, 0, 0, 31, direction, setpoint, 0.0, 0.0, 0.0, False,
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
