"""The motor rule of final_control.ino: effort without progress (``noEffect``), whose it
is, one motor's or the chair's load (``effortOf``, ``effortLeads``), and what the
motors' currents say of it (``motorDraws``, ``motorSilent``) (docs/safety.md, "One
motor or the chair's load" and "What the currents say").

``control_tick`` asks each wheel's ``no_effect`` and, for a wheel that trips, whether
its effort leads its partner's. A motor that draws what its effort calls for works: its
effort without progress is its wheel's load, and it is not blamed. If its partner then
draws nothing of what its own duty and speed call for, the partner is the dead one.
"""

from __future__ import annotations

from wcdrive.avr.f32 import add, from_int, mul, neg, sub
from wcdrive.firmware import constants as C
from wcdrive.firmware.stall import sense_amps

__all__ = ["Effort", "effort_leads", "effort_of", "motor_draws", "motor_silent", "no_effect"]

Effort = tuple[int, float, float, int]


def no_effect(applied_pwm: int, applied_dir: int, setpoint: float, measured: float, other: float,
              other_pwm: int, other_overruns: bool, effort: Effort) -> tuple[bool, Effort]:
    """``noEffect``: effort without progress, by a wheel that trails ``other`` (the other
    wheel's measured speed), as a dragged one does (the duty FAULT_EFFORT_PWM above its
    lowest, or at full duty, which can rise no more, with ``other_pwm`` no more than
    FAULT_EFFORT_PWM below it: the chair at its top speed, not the outer wheel of a
    turn), judged from where the wheel last
    turned faster than its setpoint (being slowed to it). ``effort`` is (lowest duty,
    speed toward the setpoint, setpoint, ticks) of the reference; returns (tripped, the
    new one). The other wheel driven on beyond its setpoint (``other_overruns``:
    ``overruns``) starts the count over: a chair not following its command. Whose load
    it is, one motor's or the chair's, is the caller's (``effort_leads``)."""
    effort_pwm, effort_speed, effort_setpoint, ticks = effort
    progress = measured if setpoint > 0.0 else -measured
    toward = setpoint != 0.0 and (applied_dir == C.HIGH) == (setpoint > 0.0)
    if not toward or setpoint != effort_setpoint or progress > effort_speed or progress > abs(setpoint):
        return False, (applied_pwm, progress, setpoint, 0)
    effort_pwm = min(effort_pwm, applied_pwm)
    shortfall = abs(measured) < mul(C.FAULT_EFFORT_SHORTFALL_MOTOR, abs(setpoint))
    other_progress = other if setpoint > 0.0 else -other
    trails = progress < add(max(other_progress, 0.0), C.FAULT_EFFORT_LEAD)
    rose = (applied_pwm >= effort_pwm + C.FAULT_EFFORT_PWM
            or (applied_pwm == 255 and other_pwm + C.FAULT_EFFORT_PWM >= 255))
    ticks = (ticks + 1) & 0xFF if shortfall and trails and not other_overruns and rose else 0
    return ticks >= C.FAULT_EFFORT_TICKS, (effort_pwm, effort_speed, effort_setpoint, ticks)


def effort_of(applied_pwm: int, applied_dir: int, setpoint: float, measured: float) -> float:
    """``effortOf``: the duty toward the setpoint (against it, negative) less what the
    back-EMF of the wheel's speed that way takes (FAULT_EFFORT_EMF per rad/s): the share
    of the duty that drives current (negative: braking); within FAULT_EFFORT_MAX either
    way (the driver's current limit: more gives no more torque). 0 without a setpoint."""
    if setpoint == 0.0:
        return 0.0
    forward = setpoint > 0.0
    duty = float(applied_pwm) if (applied_dir == C.HIGH) == forward else -float(applied_pwm)
    progress = measured if forward else -measured
    effort = sub(duty, mul(C.FAULT_EFFORT_EMF, progress))
    if effort <= -C.FAULT_EFFORT_MAX:
        return -C.FAULT_EFFORT_MAX
    return effort if effort < C.FAULT_EFFORT_MAX else C.FAULT_EFFORT_MAX


def effort_leads(applied_pwm: int, applied_dir: int, setpoint: float, measured: float,
                 other_pwm: int, other_dir: int, other_setpoint: float, other: float) -> bool:
    """``effortLeads``: the wheel's effort leads the other wheel's by
    FAULT_EFFORT_LEAD_PWM or more, the other not held back by its own setpoint
    (FAULT_EFFORT_OVERRUN or more beyond it this wheel's way); or it should brake at the
    current limit while the other brakes FAULT_EFFORT_LEAD_PWM less, yet its duty winds
    up without a gain (a dead wheel carried down a grade); or, both at FAULT_EFFORT_MAX
    (the current limit) and the other short of its setpoint, it turns FAULT_EFFORT_LAG
    slower than the other, each its own way, beyond what the setpoints ask (a setpoint
    asking this wheel for more is no excuse: at the limit neither gets its setpoint).
    One motor doing nothing while its partner carries the chair, not a load both wheels
    share (a grade, a kerb, a ramp's edge)."""
    effort = effort_of(applied_pwm, applied_dir, setpoint, measured)
    other_effort = effort_of(other_pwm, other_dir, other_setpoint, other)
    other_progress = other if other_setpoint > 0.0 else -other
    # a partner braking down to its setpoint works as hard as one driving
    braking_down = other_effort < 0.0 and other_progress > abs(other_setpoint)
    other_work = -other_effort if braking_down else other_effort
    # a partner held back by its own setpoint (a spin, a sharp turn, a stop) holds the
    # chair back: this wheel's effort goes into that
    held_back = sub(other, other_setpoint) if setpoint > 0.0 else sub(other_setpoint, other)
    # a partner braking below the current limit while short of its setpoint by
    # FAULT_EFFORT_SHORTFALL of it and FAULT_EFFORT_OVERRUN (its PID unwinding after a
    # descent or a cut of its setpoint) slows the chair of its own accord; one braking at
    # the limit may be holding a dead wheel's chair
    braking_short = (-C.FAULT_EFFORT_MAX < other_effort < 0.0
                     and other_progress < mul(C.FAULT_EFFORT_SHORTFALL, abs(other_setpoint))
                     and other_progress < sub(abs(other_setpoint), C.FAULT_EFFORT_OVERRUN))
    if (held_back < C.FAULT_EFFORT_OVERRUN and not braking_short
            and effort >= add(other_work, C.FAULT_EFFORT_LEAD_PWM)):
        return True
    if effort <= -C.FAULT_EFFORT_MAX and other_effort >= add(effort, C.FAULT_EFFORT_LEAD_PWM):
        return True
    if effort < C.FAULT_EFFORT_MAX or other_effort < C.FAULT_EFFORT_MAX:
        return False
    progress = measured if setpoint > 0.0 else -measured
    if other_progress >= abs(other_setpoint):
        return False
    asked = sub(abs(other_setpoint), abs(setpoint))
    return sub(sub(other_progress, progress), asked if asked > 0.0 else 0.0) >= C.FAULT_EFFORT_LAG


def motor_draws(applied_pwm: int, applied_dir: int, setpoint: float, measured: float, delta: int,
                current: int) -> bool:
    """``motorDraws``: the wheel turning its setpoint's way (FAULT_STANDING_SPEED or more
    toward it, and counting this tick: ``delta``, not a stand, nor a wheel just locked
    whose filtered speed lags), its motor draws MOTOR_DRAW_MIN or more the way its effort
    calls for, and MOTOR_DRAW_SHARE or more of the current that effort (its duty toward
    the setpoint less FAULT_EFFORT_EMF a rad/s of its speed that way, within
    FAULT_EFFORT_MAX, the driver's current limit: ``effort_of``'s, its clamp written out
    as the sketch has it) drives through the armature (MOTOR_AMPS_PER_DUTY a duty;
    negative, braking). It works: effort without progress is then its wheel's load (the
    chair's momentum as it comes off a ramp, a grade at the current limit), not a dead
    motor, which draws nothing. A reversed encoder's wheel turning toward its setpoint
    reads a speed against it and is never exempt; one rolled back against its setpoint
    reads progress, and is the reversal and runaway rules' (docs/safety.md, "What the
    currents say")."""
    if setpoint == 0.0 or delta == 0:
        return False
    forward = setpoint > 0.0
    progress = measured if forward else neg(measured)
    if progress < C.FAULT_STANDING_SPEED:
        return False
    duty = from_int(applied_pwm) if (applied_dir == C.HIGH) == forward else neg(from_int(applied_pwm))
    effort = sub(duty, mul(C.FAULT_EFFORT_EMF, progress))
    if effort <= neg(C.FAULT_EFFORT_MAX):
        effort = neg(C.FAULT_EFFORT_MAX)
    elif effort >= C.FAULT_EFFORT_MAX:
        effort = C.FAULT_EFFORT_MAX
    called = mul(mul(effort, C.MOTOR_AMPS_PER_DUTY), C.MOTOR_DRAW_SHARE)
    amps = sense_amps(current)
    drawn = amps if forward else neg(amps)
    if called > 0.0:
        return drawn >= C.MOTOR_DRAW_MIN and drawn >= called
    if called < 0.0:
        return drawn <= neg(C.MOTOR_DRAW_MIN) and drawn <= called
    return False


def motor_silent(applied_pwm: int, applied_dir: int, measured: float, current: int) -> bool:
    """``motorSilent``: the motor draws less than MOTOR_DRAW_MIN either way while its duty
    and its wheel's speed call for MOTOR_SILENT_CURRENT or more, either way (the duty,
    forward positive, less FAULT_EFFORT_EMF a rad/s of the measured speed, over the
    armature: MOTOR_AMPS_PER_DUTY a duty). An open winding or a dead driver: its wheel,
    carried by the chair, neither drives nor brakes."""
    duty = from_int(applied_pwm) if applied_dir == C.HIGH else neg(from_int(applied_pwm))
    called = mul(sub(duty, mul(C.FAULT_EFFORT_EMF, measured)), C.MOTOR_AMPS_PER_DUTY)
    amps = sense_amps(current)
    return abs(called) >= C.MOTOR_SILENT_CURRENT and abs(amps) < C.MOTOR_DRAW_MIN
