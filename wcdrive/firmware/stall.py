"""The motors' currents as final_control.ino measures them, and the stall timeout: the
sketch's ``senseAmps``, ``currentSenseFault``, ``heldAtLimit`` and ``heldBounds``
(docs/safety.md, "Stall timeout").

Each motor lead carries a bidirectional Hall current sensor on PIN_CURRENT_L /
PIN_CURRENT_R (A1, A2): CURRENT_ZERO_COUNTS at 0 A, CURRENT_AMPS_PER_COUNT amps a count,
above it for a current that drives the wheel forward (DIR HIGH). The ADC interrupt
converts both after a tick has begun; the next tick reads them (``currentTickL``/``R``).

A wheel held at its current limit (``held_at_limit``: the wheel standing, STALL_CREEP_COUNTS
at most, beside a partner that stands too or pivots the chair about it in a spin
(``spins_about``), the wheel driven toward its setpoint at
FAULT_STALL_PWM_STANDING or more, its motor drawing STALL_CURRENT or more the way it is
driven) is not an encoder fault: ``check_wheel`` does not count it toward ENC_STALL or
DRIVER_DEAD, nor its effort toward MOTOR_L/R, and its PID runs within
STALL_HELD_OUTPUT (``held_bounds``), the motor's full torque at a standstill (the
integral back-calculated to it: no wind-up to spend when it next counts). Its current
then bounds how fast it can turn: at 24 V, duty 42 less the 35 that drive 11 A through
the armature leaves 7 for back-EMF, 0.5 rad/s. A cut encoder's wheel that turns faster
draws less and is a stalled encoder; a dead driver draws nothing; a wheel pushed faster
than its duty turns it draws a braking current, which does not count. While a wheel is
held, driving (not under the hold), the tick runs the stall clock (``stallTime``,
seconds; a fault sets it to 0); at ``stallTimeout`` (the parameter ``stall_timeout``,
STALL_TIMEOUT by default) the chair stops as at its other limits
(``EVT:STALL_TIMEOUT``, the emergency ramp and the hold) and motion needs a neutral
command. A sense that reads beyond CURRENT_SENSE_MAX either way (a cut or shorted
output) latches ``CURRENT_SENSE``.

Below the current limit the currents say two more things the encoders cannot. A wheel
driven toward its setpoint whose motor draws STANDING_DRAW_SHARE of what its duty
drives through a standing armature, its partner short of its own setpoint
(``stands_by_current``), stands under a load (across a grade, say): below full torque
it stalls only after FAULT_STALL_TICKS_LOADED count-less ticks. A motor whose wheel turns
its way, drawing MOTOR_DRAW_SHARE of what its effort calls for (``motor_draws``),
works, so its effort without progress is its load, never MOTOR_L/R.
"""

from __future__ import annotations

from wcdrive.avr.f32 import from_int, mul, neg
from wcdrive.firmware import constants as C

__all__ = ["FAULT_CURRENT_SENSE", "current_sense_fault", "held_at_limit", "held_bounds", "sense_amps",
           "spins_about", "stands_by_current"]

FAULT_CURRENT_SENSE = 0x4000


def sense_amps(count: int) -> float:
    """``senseAmps``: the current an ADC count of a current sense reads, A: positive
    drives the wheel forward (DIR HIGH), negative backward (or brakes a wheel driven
    forward)."""
    return mul(from_int(count - C.CURRENT_ZERO_COUNTS), C.CURRENT_AMPS_PER_COUNT)


def current_sense_fault(count_l: int, count_r: int) -> int:
    """``currentSenseFault``: FAULT_CURRENT_SENSE when either sense reads beyond
    CURRENT_SENSE_MAX."""
    if abs(sense_amps(count_l)) > C.CURRENT_SENSE_MAX or abs(sense_amps(count_r)) > C.CURRENT_SENSE_MAX:
        return FAULT_CURRENT_SENSE
    return 0


def held_at_limit(delta: int, other_delta: int, applied_pwm: int, applied_dir: int, setpoint: float,
                  current: int, other_setpoint: float, other: float) -> bool:
    """``heldAtLimit``: the wheel standing (STALL_CREEP_COUNTS this tick at most, either
    way: ``delta``), driven toward its setpoint at FAULT_STALL_PWM_STANDING or more, its
    motor drawing STALL_CURRENT or more the way it is driven (a braking current, a wheel
    pushed faster than its duty turns it, is not: it says nothing of a stand), beside a
    partner that stands too (``other_delta`` within STALL_CREEP_COUNTS) or that pivots
    the chair about it (``spins_about``). Its PID then runs within STALL_HELD_OUTPUT
    (``held_bounds``), so that a current that high bounds how fast it turns; a partner
    that counts its way beside it, the same way (a chair crawling up a grade at its
    limit), leaves a count-less wheel a stalled encoder."""
    amps = sense_amps(current)
    drawn = amps if applied_dir == C.HIGH else -amps
    return (abs(delta) <= C.STALL_CREEP_COUNTS
            and (abs(other_delta) <= C.STALL_CREEP_COUNTS or spins_about(setpoint, other_setpoint, other))
            and applied_pwm >= C.FAULT_STALL_PWM_STANDING
            and setpoint != 0.0 and (applied_dir == C.HIGH) == (setpoint > 0.0)
            and drawn >= C.STALL_CURRENT)


def spins_about(setpoint: float, other_setpoint: float, other: float) -> bool:
    """``spinsAbout``: a spin asked (the partner's setpoint the other way from this
    wheel's) and the partner standing or turning its own setpoint's way (``other``, its
    measured speed): the chair pivots about this wheel, as a spin on a grade does when
    the wheel that would turn the chair uphill stands at its current limit (the grade
    turns a chair whose weight is ahead of its drive axle downhill). A partner turning
    this wheel's way would show the chair moving, and this wheel with it. A cut encoder's
    wheel drawing that current turns at most 0.5 rad/s (``held_bounds``), until the stall
    timeout."""
    if setpoint == 0.0 or other_setpoint == 0.0 or (other_setpoint > 0.0) == (setpoint > 0.0):
        return False
    along = other if other_setpoint > 0.0 else neg(other)
    return along >= 0.0


def held_bounds(lo: float, hi: float) -> tuple[float, float]:
    """``heldBounds``: the PID's bounds ``lo``, ``hi`` (``pid_bounds``) within
    STALL_HELD_OUTPUT either way, for a wheel held at its current limit."""
    if hi > C.STALL_HELD_OUTPUT:
        hi = C.STALL_HELD_OUTPUT
    if lo < -C.STALL_HELD_OUTPUT:
        lo = -C.STALL_HELD_OUTPUT
    return lo, hi


def stands_by_current(applied_pwm: int, applied_dir: int, setpoint: float, current: int,
                      other_setpoint: float, other: float) -> bool:
    """``standsByCurrent``: the wheel driven toward its setpoint, its motor drawing
    STANDING_DRAW_SHARE or more of the current its duty drives through a standing
    armature (MOTOR_AMPS_PER_DUTY a duty), and MOTOR_DRAW_MIN at the least, the way it is
    driven: its back-EMF, so its
    speed, is a quarter of what its duty would turn it at or less (0.73 rad/s at duty 41,
    24 V); and its partner short of its own setpoint (slower than FAULT_EFFORT_SHORTFALL
    of it its way, ``other`` its measured speed): the chair is loaded, not this wheel
    alone. Below FAULT_STALL_PWM_STANDING ``check_wheel`` then counts
    FAULT_STALL_TICKS_LOADED count-less ticks before a stall: a wheel standing under a
    load at the edge of moving creeps a count every tick or two, a locked wheel counts
    none; a cut encoder's wheel that turns draws less, and a wheel that stands while its
    partner keeps its setpoint is blocked alone."""
    if setpoint == 0.0 or (applied_dir == C.HIGH) != (setpoint > 0.0):
        return False
    other_progress = other if other_setpoint > 0.0 else neg(other)
    if other_progress >= mul(C.FAULT_EFFORT_SHORTFALL, abs(other_setpoint)):
        return False
    amps = sense_amps(current)
    drawn = amps if applied_dir == C.HIGH else neg(amps)
    return (drawn >= C.MOTOR_DRAW_MIN
            and drawn >= mul(C.STANDING_DRAW_SHARE, mul(from_int(applied_pwm), C.MOTOR_AMPS_PER_DUTY)))
