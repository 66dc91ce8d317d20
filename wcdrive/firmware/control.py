"""The control tick of final_control.ino: velocity, filter, fault checks, watchdog,
ramp, parking and braking, PID with back-calculation anti-windup, motor outputs, pivot
and feedback."""

from __future__ import annotations

from wcdrive.avr.f32 import add, div, from_int, mul, neg, sub
from wcdrive.firmware import constants as C
from wcdrive.firmware.battery import battery_fault, send_battery_event, update_supply
from wcdrive.firmware.brake import (
    BRAKE_RELEASED,
    brake_coil_fault,
    brake_step,
    braking_output,
    braking_setpoint,
)
from wcdrive.firmware.drive import ramp_setpoints
from wcdrive.firmware.inhibit import capped_goals, send_inhibit_event, update_inhibits
from wcdrive.firmware.motion import PIVOT_NONE, confirm_neutral, emergency_halt, pivot_step, require_neutral
from wcdrive.firmware.motor_rule import Effort, effort_leads, effort_of, motor_draws, motor_silent, no_effect
from wcdrive.firmware.motors import i32, motors
from wcdrive.firmware.output import (
    feedback_line,
    refill_credit,
    send,
    send_event,
    send_fault_events,
    send_telemetry,
)
from wcdrive.firmware.stall import current_sense_fault, held_at_limit, held_bounds, stands_by_current
from wcdrive.firmware.state import FirmwareState
from wcdrive.firmware.thermal import (
    pid_bounds,
    send_thermal_event,
    thermal_fault,
    update_thermal,
)

_OUT_MAX = C.PID_OUT_MAX


def compute_pid(setpoint: float, measurement: float, integral: float, prev_meas: float,
                kp: float, ki: float, kd: float, dt: float, lo: float = -_OUT_MAX,
                hi: float = _OUT_MAX) -> tuple[float, float]:
    """``computePID``: returns ``(output clamped to lo..hi, new integral)``; the
    integral is back-calculated to whichever bound binds."""
    error = sub(setpoint, measurement)
    integral = add(integral, mul(error, dt))
    limit = div(_OUT_MAX, ki)
    # constrain(integral, -limit, limit)
    integral = -limit if integral < -limit else (limit if integral > limit else integral)
    derivative = div(neg(sub(measurement, prev_meas)), dt)
    p_term = mul(kp, error)
    d_term = mul(kd, derivative)
    output = add(add(p_term, mul(ki, integral)), d_term)
    clamped = lo if output < lo else (hi if output > hi else output)
    if output != clamped:
        integral = div(sub(sub(clamped, p_term), d_term), ki)
        # never past zero: a P term beyond the clamp on its own would wind the integral
        # against the saturation, and the wheel would be driven backward once the error fell
        if (integral > 0.0) != (clamped > 0.0):
            integral = 0.0
    return clamped, integral


WHEEL_OK, WHEEL_SUSPECT, WHEEL_STALLED, WHEEL_REVERSED, WHEEL_IMPLAUSIBLE, WHEEL_NO_EFFECT = range(6)
FAULT_STALL_L, FAULT_STALL_R, FAULT_REVERSED_L, FAULT_REVERSED_R = 0x01, 0x02, 0x04, 0x08
FAULT_IMPLAUSIBLE_L, FAULT_IMPLAUSIBLE_R, FAULT_DRIVER = 0x10, 0x20, 0x40
FAULT_MOTOR_L, FAULT_MOTOR_R = 0x80, 0x100
#: The faults after which a wheel's encoder is no longer trusted: its own, and the driver's.
FAULTS_UNTRUSTED_L = FAULT_STALL_L | FAULT_REVERSED_L | FAULT_IMPLAUSIBLE_L | FAULT_MOTOR_L | FAULT_DRIVER
FAULTS_UNTRUSTED_R = FAULT_STALL_R | FAULT_REVERSED_R | FAULT_IMPLAUSIBLE_R | FAULT_MOTOR_R | FAULT_DRIVER


def stalling(setpoint: float, measured: float) -> bool:
    """``stalling``: slower than GRADE_STALL of its setpoint its way (or against it)."""
    progress = measured if setpoint > 0.0 else -measured
    return progress < mul(C.GRADE_STALL, abs(setpoint))


def overruns(applied_pwm: int, applied_dir: int, setpoint: float, measured: float) -> bool:
    """``overruns``: driven toward its setpoint (not braked) while turning
    FAULT_EFFORT_OVERRUN or more beyond it that way."""
    progress = measured if setpoint > 0.0 else -measured
    return (setpoint != 0.0 and applied_pwm > 0 and (applied_dir == C.HIGH) == (setpoint > 0.0)
            and progress > add(abs(setpoint), C.FAULT_EFFORT_OVERRUN))


def runs_away(applied_pwm: int, applied_dir: int, setpoint: float, measured: float,
              prev_measured: float) -> bool:
    """``runsAway``: braked at FAULT_RUNAWAY_PWM or more against its measured motion,
    FAULT_REVERSE_SPEED or more beyond its setpoint that way, and FAULT_RUNAWAY_GAIN or
    more faster than ``prev_measured`` (the speed the PID last ran on): a wheel whose
    encoder counts against the motion, driven harder the faster it seems to go."""
    forward = measured > 0.0
    beyond = sub(measured, setpoint) if forward else sub(setpoint, measured)
    return (applied_pwm >= C.FAULT_RUNAWAY_PWM and (applied_dir == C.HIGH) != forward
            and abs(measured) >= C.FAULT_REVERSE_SPEED and beyond >= C.FAULT_REVERSE_SPEED
            and sub(abs(measured), abs(prev_measured)) >= C.FAULT_RUNAWAY_GAIN)


def overspeeding(applied_pwm: int, applied_dir: int, setpoint: float, target: float,
                 measured: float) -> bool:
    """``overspeeding``: moving the way of its setpoint (or with none), OVERSPEED_MARGIN
    or more beyond it and beyond its target (faster than commanded), and braked at
    OVERSPEED_PWM or more against the motion."""
    forward = measured > 0.0
    beyond = sub(measured, setpoint) if forward else sub(setpoint, measured)
    beyond_target = sub(measured, target) if forward else sub(target, measured)
    along = setpoint == 0.0 or (setpoint > 0.0) == forward
    return (along and applied_pwm >= C.OVERSPEED_PWM and (applied_dir == C.HIGH) != forward
            and beyond >= C.OVERSPEED_MARGIN and beyond_target >= C.OVERSPEED_MARGIN)


def overspeed_run(over: bool, measured: float, prev_measured: float, ticks: int,
                  start: float) -> tuple[bool, int, float]:
    """``overspeedRun``: ``(gravity beats the motors, ticks, from)``. Counts a run of
    overspeeding ticks (wrapping at 256) from the speed the PID ran on before its first;
    true once the run is OVERSPEED_TICKS long and the wheel OVERSPEED_GAIN faster than that."""
    if not over:
        return False, 0, start
    if ticks == 0:
        start = abs(prev_measured)
    ticks = (ticks + 1) & 0xFF
    return ticks >= C.OVERSPEED_TICKS and sub(abs(measured), start) >= C.OVERSPEED_GAIN, ticks, start


def straining(applied_pwm: int, applied_dir: int, setpoint: float, measured: float) -> bool:
    """``straining``: driven at GRADE_PWM or more toward a setpoint it runs short of
    (slower than FAULT_EFFORT_SHORTFALL of it that way, or against it)."""
    progress = measured if setpoint > 0.0 else -measured
    return (setpoint != 0.0 and (applied_dir == C.HIGH) == (setpoint > 0.0)
            and applied_pwm >= C.GRADE_PWM
            and progress < mul(C.FAULT_EFFORT_SHORTFALL, abs(setpoint)))


def at_limit(check: int, leads: bool, stalls: bool, other_strains: bool, other_reverse: int,
             other_runaway: int, other_effort: int) -> bool:
    """``atLimit``: the chair's limit rather than a fault. No effect with an effort that
    does not lead the other wheel's (``leads``), slower than GRADE_STALL of the setpoint
    (``stalls``), while the other wheel strains or shows effort without progress too:
    a grade beyond the chair. A reversal while the other wheel strains, or its reversed,
    runaway or effort count runs: both wheels pushed back."""
    if check == WHEEL_NO_EFFECT:
        return not leads and stalls and (other_strains or other_effort != 0)
    return (check == WHEEL_REVERSED
            and (other_strains or other_reverse != 0 or other_runaway != 0 or other_effort != 0))


def stalls_loaded(setpoint: float, prev_measured: float, other: float) -> bool:
    """``stallsLoaded``: a stalled wheel that stood (slower than FAULT_STANDING_SPEED
    when the PID last ran) while the other wheel rolls FAULT_STANDING_SPEED or more
    against this wheel's setpoint: the chair pivots back about the standing wheel, which
    its full torque (FAULT_STALL_PWM_STANDING) cannot move: the chair's limit. A cut
    encoder's wheel turns its way and carries the chair with it."""
    along = other if setpoint > 0.0 else -other
    return abs(prev_measured) < C.FAULT_STANDING_SPEED and along <= -C.FAULT_STANDING_SPEED


def check_wheel(delta: int, illegal: int, storm: int, applied_pwm: int, applied_dir: int,
                setpoint: float, measured: float, other: float, other_pwm: int, other_overruns: bool,
                stall_ticks: int, reverse_ticks: int, runaway_ticks: int,
                effort: Effort, prev_measured: float, holding: int,
                held: bool = False, loaded: bool = False) -> tuple[int, int, int, int, Effort]:
    """``checkWheel``: ``(verdict, stall ticks, reverse ticks, runaway ticks, effort
    reference)`` for one wheel over the interval that ended: WHEEL_OK, WHEEL_SUSPECT
    (hold the output), or a fault. A stall is a duty toward a non-zero setpoint without
    a count (braking ends with none), FAULT_STALL_TICKS_TURNING ticks long for a wheel
    turning round (``prev_measured`` against the setpoint). A measured speed against the
    setpoint counts toward a reversed encoder unless the wheel came FAULT_REVERSE_APPROACH closer to the
    setpoint since ``prev_measured`` (the speed the PID last ran on): a healthy wheel
    lagging a reversal of its setpoint slows toward it, a reversed encoder shows it
    moving away. A runaway (``runs_away``) counts one up a tick; driving, any other tick
    counts one down (to 0), so a wavering speed-up is not started over; ``holding``, it
    starts over (the hold's wheels rolled back by a grade beyond it). FAULT_RUNAWAY_TICKS
    is a reversed encoder too: the one whose reading flipped sign with its setpoint.
    ``held``, ``loaded``: ``held_at_limit``, ``stands_by_current`` (``stall``)."""
    if storm or illegal >= C.FAULT_ILLEGAL_PER_TICK:
        return WHEEL_IMPLAUSIBLE, stall_ticks, reverse_ticks, runaway_ticks, effort
    # a wheel that stands while its partner does not carry the chair its way (stands, or
    # rolls back) may stand on a grade below the motor's full torque
    other_along = other if setpoint > 0.0 else -other
    standing = abs(prev_measured) < C.FAULT_STANDING_SPEED and other_along < C.FAULT_STANDING_SPEED
    stall_pwm = C.FAULT_STALL_PWM_STANDING if standing else C.FAULT_STALL_PWM
    driven = (applied_pwm >= stall_pwm and setpoint != 0.0
              and (applied_dir == C.HIGH) == (setpoint > 0.0))
    # held at its current limit (held_at_limit): the stall timeout's, not a stalled encoder
    stalled = driven and delta == 0 and not held
    stall_ticks = (stall_ticks + 1) & 0xFF if stalled else 0
    turning = prev_measured != 0.0 and (prev_measured > 0.0) != (setpoint > 0.0)
    limit = (C.FAULT_STALL_TICKS_LOADED if loaded and applied_pwm < C.FAULT_STALL_PWM_STANDING  # loaded
             else C.FAULT_STALL_TICKS_TURNING if turning else C.FAULT_STALL_TICKS)
    if stall_ticks >= limit:
        return WHEEL_STALLED, stall_ticks, reverse_ticks, runaway_ticks, effort
    approach = sub(measured, prev_measured) if setpoint > 0.0 else sub(prev_measured, measured)
    # a wheel driven the way it reads (its PID still drives it the way it went) agrees
    # with its encoder: a reversed encoder reads against the way its wheel is driven
    drives_its_way = applied_pwm > 0 and (applied_dir == C.HIGH) == (measured > 0.0)
    against = (abs(setpoint) >= C.FAULT_REVERSE_SPEED and abs(measured) >= C.FAULT_REVERSE_SPEED
               and (setpoint > 0.0) != (measured > 0.0) and approach < C.FAULT_REVERSE_APPROACH
               and not drives_its_way)
    reverse_ticks = (reverse_ticks + 1) & 0xFF if against else 0
    if reverse_ticks >= C.FAULT_REVERSE_TICKS:
        return WHEEL_REVERSED, stall_ticks, reverse_ticks, runaway_ticks, effort
    running = runs_away(applied_pwm, applied_dir, setpoint, measured, prev_measured)
    if running:
        runaway_ticks = (runaway_ticks + 1) & 0xFF
    else:
        runaway_ticks = runaway_ticks - 1 if runaway_ticks > 0 and not holding else 0
    if runaway_ticks >= C.FAULT_RUNAWAY_TICKS:
        return WHEEL_REVERSED, stall_ticks, reverse_ticks, runaway_ticks, effort
    tripped, effort = no_effect(applied_pwm, applied_dir, setpoint, measured, other, other_pwm,
                                other_overruns, effort)
    if held:        # held at its current limit, its motor draws it: no dead motor, no effort
        effort = (effort[0], effort[1], effort[2], 0)
    elif tripped:
        return WHEEL_NO_EFFECT, stall_ticks, reverse_ticks, runaway_ticks, effort
    verdict = WHEEL_SUSPECT if stalled or against else WHEEL_OK
    return verdict, stall_ticks, reverse_ticks, runaway_ticks, effort


def wheel_faults(check: int, stall: int, reversed_: int, implausible: int, motor: int) -> int:
    """``wheelFaults``: the fault bits of one wheel's verdict."""
    if check == WHEEL_STALLED:
        return stall
    if check == WHEEL_REVERSED:
        return reversed_
    if check == WHEEL_IMPLAUSIBLE:
        return implausible
    if check == WHEEL_NO_EFFECT:
        return motor
    return 0


def _check_faults(s: FirmwareState, delta_l: int, delta_r: int, ill_l: int, ill_r: int, dt: float,
                  out: bytearray) -> tuple[int, int, bool, bool, bool, bool]:
    """The tick's fault checks (until one latches); a new fault halts the chair and
    sends its events. The chair's limits are not faults: an overspeed
    (``EVT:OVERSPEED``) or, driving, both wheels at their limit (``EVT:STALLED_ON_GRADE``)
    park it under the hold, and so does a wheel held at its current limit for
    ``stallTimeout`` s (``EVT:STALL_TIMEOUT``). Returns both wheels' verdicts, whether
    to park (halt), whether the hold brakes hardest from the start and whether each
    wheel is held at its current limit (``held_at_limit``)."""
    if s.faultFlags:
        return WHEEL_OK, WHEEL_OK, False, False, False, False
    strain_l = straining(s.pwmL, s.dirL, s.setpointL, s.filtVelL)
    strain_r = straining(s.pwmR, s.dirR, s.setpointR, s.filtVelR)
    overrun_l = overruns(s.pwmL, s.dirL, s.setpointL, s.filtVelL)
    overrun_r = overruns(s.pwmR, s.dirR, s.setpointR, s.filtVelR)
    held_l = held_at_limit(delta_l, delta_r, s.pwmL, s.dirL, s.setpointL, s.currentTickL, s.setpointR,
                           s.filtVelR)
    held_r = held_at_limit(delta_r, delta_l, s.pwmR, s.dirR, s.setpointR, s.currentTickR, s.setpointL,
                           s.filtVelL)
    loaded_l = stands_by_current(s.pwmL, s.dirL, s.setpointL, s.currentTickL, s.setpointR, s.filtVelR)
    loaded_r = stands_by_current(s.pwmR, s.dirR, s.setpointR, s.currentTickR, s.setpointL, s.filtVelL)
    check_l, s.stallTicksL, s.reverseTicksL, s.runawayTicksL, effort_l = check_wheel(
        delta_l, ill_l, s.stormTickL, s.pwmL, s.dirL, s.setpointL, s.filtVelL, s.filtVelR,
        s.pwmR, overrun_r, s.stallTicksL, s.reverseTicksL, s.runawayTicksL,
        (s.effortPwmL, s.effortSpeedL, s.effortSetpointL, s.effortTicksL),
        s.prevMeasL, s.holding, held_l, loaded_l)
    s.effortPwmL, s.effortSpeedL, s.effortSetpointL, s.effortTicksL = effort_l
    check_r, s.stallTicksR, s.reverseTicksR, s.runawayTicksR, effort_r = check_wheel(
        delta_r, ill_r, s.stormTickR, s.pwmR, s.dirR, s.setpointR, s.filtVelR, s.filtVelL,
        s.pwmL, overrun_l, s.stallTicksR, s.reverseTicksR, s.runawayTicksR,
        (s.effortPwmR, s.effortSpeedR, s.effortSetpointR, s.effortTicksR),
        s.prevMeasR, s.holding, held_r, loaded_r)
    s.effortPwmR, s.effortSpeedR, s.effortSetpointR, s.effortTicksR = effort_r
    # driving, a wheel held at its current limit runs the stall timeout's clock
    s.stallTime = add(s.stallTime, dt) if not s.holding and (held_l or held_r) else 0.0
    # Effort without progress is one motor's while it leads and the motor does not draw
    # what its effort calls for, turning or standing loaded. A partner that draws nothing
    # of what its own duty and speed call for is then the dead one.
    draws_l = loaded_l or motor_draws(s.pwmL, s.dirL, s.setpointL, s.filtVelL, delta_l, s.currentTickL)
    draws_r = loaded_r or motor_draws(s.pwmR, s.dirR, s.setpointR, s.filtVelR, delta_r, s.currentTickR)
    lead_l = check_l == WHEEL_NO_EFFECT and effort_leads(
        s.pwmL, s.dirL, s.setpointL, s.filtVelL, s.pwmR, s.dirR, s.setpointR, s.filtVelR)
    lead_r = check_r == WHEEL_NO_EFFECT and effort_leads(
        s.pwmR, s.dirR, s.setpointR, s.filtVelR, s.pwmL, s.dirL, s.setpointL, s.filtVelL)
    leads_l, leads_r = lead_l and not draws_l, lead_r and not draws_r
    if (lead_l and draws_l and check_r in (WHEEL_OK, WHEEL_SUSPECT, WHEEL_NO_EFFECT)
            and motor_silent(s.pwmR, s.dirR, s.filtVelR, s.currentTickR)):
        check_r, leads_r = WHEEL_NO_EFFECT, True
    if (lead_r and draws_r and check_l in (WHEEL_OK, WHEEL_SUSPECT, WHEEL_NO_EFFECT)
            and motor_silent(s.pwmL, s.dirL, s.filtVelL, s.currentTickL)):
        check_l, leads_l = WHEEL_NO_EFFECT, True
    # Driving only: a held wheel that runs away is a fault (a reversed encoder turns the
    # hold into positive feedback), whatever the other wheel does.
    limit_l = not s.holding and at_limit(check_l, leads_l, stalling(s.setpointL, s.filtVelL), strain_r,
                                         s.reverseTicksR, s.runawayTicksR, s.effortTicksR)
    limit_r = not s.holding and at_limit(check_r, leads_r, stalling(s.setpointR, s.filtVelR), strain_l,
                                         s.reverseTicksL, s.runawayTicksL, s.effortTicksL)
    # a wheel that stood at full torque while its partner rolled back against its way:
    # the chair pivots back about it, beyond what the motors hold (a turn on a grade)
    if not s.holding and check_l == WHEEL_STALLED and check_r != WHEEL_STALLED:
        limit_l = limit_l or stalls_loaded(s.setpointL, s.prevMeasL, s.filtVelR)
    if not s.holding and check_r == WHEEL_STALLED and check_l != WHEEL_STALLED:
        limit_r = limit_r or stalls_loaded(s.setpointR, s.prevMeasR, s.filtVelL)
    # the limit, or a load both wheels share short of it (no lead): not a fault
    if limit_l or (check_l == WHEEL_NO_EFFECT and not leads_l):
        check_l = WHEEL_OK
    if limit_r or (check_r == WHEEL_NO_EFFECT and not leads_r):
        check_r = WHEEL_OK
    over_l, s.overspeedTicksL, s.overspeedFromL = overspeed_run(
        not s.holding and overspeeding(s.pwmL, s.dirL, s.setpointL, s.targetL, s.filtVelL),
        s.filtVelL, s.prevMeasL, s.overspeedTicksL, s.overspeedFromL)
    over_r, s.overspeedTicksR, s.overspeedFromR = overspeed_run(
        not s.holding and overspeeding(s.pwmR, s.dirR, s.setpointR, s.targetR, s.filtVelR),
        s.filtVelR, s.prevMeasR, s.overspeedTicksR, s.overspeedFromR)
    # one wheel gaining speed however hard it is braked, OVERSPEED_ONE_TICKS ticks, the
    # other braking at the current limit too (going down a grade) and holding: its motor
    # does not brake (gravity beating both is OVERSPEED; a wheel pushed on while its
    # partner drives is the runaway rule's)
    if (over_l and s.overspeedTicksL >= C.OVERSPEED_ONE_TICKS and s.overspeedTicksR == 0
            and effort_of(s.pwmR, s.dirR, s.setpointR, s.filtVelR) <= -C.FAULT_EFFORT_MAX
            and check_l in (WHEEL_OK, WHEEL_SUSPECT)):
        check_l = WHEEL_NO_EFFECT
    if (over_r and s.overspeedTicksR >= C.OVERSPEED_ONE_TICKS and s.overspeedTicksL == 0
            and effort_of(s.pwmL, s.dirL, s.setpointL, s.filtVelL) <= -C.FAULT_EFFORT_MAX
            and check_r in (WHEEL_OK, WHEEL_SUSPECT)):
        check_r = WHEEL_NO_EFFECT
    if check_l == WHEEL_STALLED and check_r == WHEEL_STALLED:
        faults = FAULT_DRIVER
    else:
        faults = (
            wheel_faults(check_l, FAULT_STALL_L, FAULT_REVERSED_L, FAULT_IMPLAUSIBLE_L, FAULT_MOTOR_L)
            | wheel_faults(check_r, FAULT_STALL_R, FAULT_REVERSED_R, FAULT_IMPLAUSIBLE_R, FAULT_MOTOR_R))
    if not faults:
        faults = brake_coil_fault(s)
    if not faults:
        faults = thermal_fault(s)
    if not faults:
        faults = battery_fault(s)
    if not faults:
        faults = current_sense_fault(s.currentTickL, s.currentTickR)
    if faults:
        s.faultFlags = faults
        s.stallTime = 0.0
        emergency_halt(s)
        s.cmdSinceTick = 0
        s.watchdogArmed = 0
        s.stallTicksL = s.stallTicksR = s.reverseTicksL = s.reverseTicksR = 0
        s.runawayTicksL = s.runawayTicksR = 0
        send_fault_events(s, faults, out)
        return check_l, check_r, False, False, held_l, held_r
    halt = hardest = False
    # both wheels: gravity on the whole chair (one alone is its motor's fault, above)
    if over_l and over_r:
        halt = hardest = True
        send(s, send_event("OVERSPEED"), out)
    elif limit_l or limit_r:
        halt = True
        send(s, send_event("STALLED_ON_GRADE"), out)
    elif s.stallTime >= s.stallTimeout:
        # held at the current limit too long (a wall, a kerb): motion needs a neutral command
        halt = True
        require_neutral(s)
        send(s, send_event("STALL_TIMEOUT"), out)
    if halt:
        s.limitLatched = 1
        emergency_halt(s)
        s.setpointL = s.setpointR = 0.0
        s.stallTicksL = s.stallTicksR = s.reverseTicksL = s.reverseTicksR = 0
        s.runawayTicksL = s.runawayTicksR = 0
        s.effortTicksL = s.effortTicksR = 0
        s.overspeedTicksL = s.overspeedTicksR = 0
        s.stallTime = 0.0
    return check_l, check_r, halt, hardest, held_l, held_r


def control_tick(s: FirmwareState, now: int, count_l: int, count_r: int, out: bytearray,
                 illegal_l: int = 0, illegal_r: int = 0, storm_l: int = 0, storm_r: int = 0,
                 rx_lost: int = 0, inputs: int = 0, supply: int = C.SUPPLY_NOMINAL_COUNTS,
                 current_l: int = C.CURRENT_ZERO_COUNTS, current_r: int = C.CURRENT_ZERO_COUNTS) -> None:
    """``controlTick(now)`` with what it latches atomically from the interrupts: the
    encoder counts, the illegal-transition counts, the storm flags and the RX
    interrupt's count of lost bytes (``rxLost``); and the input pins it reads
    (``inputs``: bit 0 inhibit input 1, bit 1 input 2, 1 active; bit 2 the brake
    driver's status LOW; bit 3 the brake's manual release pulled, push mode), the ADC
    count it reads at PIN_SUPPLY (``supply``) and the counts of the motors' currents the
    ADC interrupt converted after the last tick began (``current_l``, ``current_r``)."""
    last_tick = s.lastControlTime if s.lastTickTime is None else s.lastTickTime
    elapsed = (now - last_tick) & 0xFFFFFFFF            # since the last tick ran
    dt = div(from_int(elapsed), 1000.0)
    s.lastTickTime = now & 0xFFFFFFFF
    # The fixed grid: due a period after the last was due; more than a period late, the
    # grid restarts from now (lateTicks).
    if ((now - s.lastControlTime) & 0xFFFFFFFF) >= 2 * C.CONTROL_PERIOD_MS:
        s.lastControlTime = now & 0xFFFFFFFF
        s.lateTicks = (s.lateTicks + 1) & 0xFFFFFFFF
    else:
        s.lastControlTime = (s.lastControlTime + C.CONTROL_PERIOD_MS) & 0xFFFFFFFF
    refill_credit(s, elapsed)
    s.tickCount = (s.tickCount + 1) & 0xFFFFFFFF

    s.encTickL, s.encTickR = i32(count_l), i32(count_r)
    ill_l = (illegal_l - s.illTickL) & 0xFFFFFFFF
    ill_r = (illegal_r - s.illTickR) & 0xFFFFFFFF
    s.illTickL, s.illTickR = illegal_l & 0xFFFFFFFF, illegal_r & 0xFFFFFFFF
    s.stormTickL, s.stormTickR = int(bool(storm_l)), int(bool(storm_r))
    s.rxLostTick = rx_lost & 0xFFFFFFFF
    s.inhibitTick = (inputs & 3) | ((inputs >> 3) & 1) << 2
    s.brakeStatusTick = (inputs >> 2) & 1
    s.supplyTick = supply & 0x3FF
    s.currentTickL, s.currentTickR = current_l & 0x3FF, current_r & 0x3FF
    delta_l = i32(s.encTickL - s.prevEncL)
    delta_r = i32(s.encTickR - s.prevEncR)
    s.prevEncL, s.prevEncR = s.encTickL, s.encTickR

    per_second = div(C.TWO_PI, dt)
    s.rawVelL = mul(neg(div(from_int(delta_l), C.CPR)), per_second)
    s.rawVelR = mul(div(from_int(delta_r), C.CPR), per_second)
    s.filtVelL = add(mul(C.ALPHA, s.rawVelL), mul(C.ONE_MINUS_ALPHA, s.filtVelL))
    s.filtVelR = add(mul(C.ALPHA, s.rawVelR), mul(C.ONE_MINUS_ALPHA, s.filtVelR))

    update_thermal(s, dt)
    update_supply(s)
    check_l, check_r, halt, hardest, held_l, held_r = _check_faults(s, delta_l, delta_r, ill_l, ill_r, dt,
                                                                    out)

    update_inhibits(s)
    if s.cmdSinceTick:
        s.cmdSinceTick = 0
        s.lastCmdTime = now & 0xFFFFFFFF
        s.watchdogArmed = 1
    if s.watchdogArmed and ((now - s.lastCmdTime) & 0xFFFFFFFF) >= s.watchdogMs:
        # a stop of motion the host asked for: the link back, its first command is neutral
        driving = s.targetL != 0.0 or s.targetR != 0.0 or s.pivotPhase != PIVOT_NONE
        s.watchdogArmed = 0
        emergency_halt(s)
        if driving:
            require_neutral(s)
        send(s, send_event("WATCHDOG"), out)
    elif s.inhibitPending:              # one a tick, in the wait for neutral's slot
        send_inhibit_event(s, out)
    elif s.thermalPending:              # ...and so are the rollbacks'
        send_thermal_event(s, out)
    elif s.batteryPending:
        send_battery_event(s, out)
    elif s.needNeutral:
        confirm_neutral(s, out)

    goal_l, goal_r = capped_goals(s)
    if s.brakeFitted and s.brakePhase != BRAKE_RELEASED:
        goal_l = goal_r = 0.0           # the brake not yet let go: the setpoints wait at zero
    ramp_setpoints(s, goal_l, goal_r, dt)
    if s.brakeFitted and s.faultFlags:
        # the brake applied at the fault: the PID may brake the wheels with it, never drive
        s.setpointL = braking_setpoint(s.setpointL, s.filtVelL)
        s.setpointR = braking_setpoint(s.setpointR, s.filtVelR)
    # Stopped (target and setpoint zero, no pivot under way), an integral that drives a
    # wheel the way it still turns is dropped: it held the chair up a grade and would carry
    # it on past the stop.
    if s.pivotPhase == PIVOT_NONE:
        if (s.targetL == 0.0 and s.setpointL == 0.0 and s.integralL != 0.0
                and (s.integralL > 0.0) == (s.filtVelL > 0.0)):
            s.integralL = 0.0
        if (s.targetR == 0.0 and s.setpointR == 0.0 and s.integralR != 0.0
                and (s.integralR > 0.0) == (s.filtVelR > 0.0)):
            s.integralR = 0.0

    still = abs(s.filtVelL) < C.STILL_SPEED and abs(s.filtVelR) < C.STILL_SPEED
    if not still:
        s.stillTicks = 0
    elif s.stillTicks < 255:
        s.stillTicks += 1
    at_rest = s.targetL == 0.0 and s.targetR == 0.0 and s.setpointL == 0.0 and s.setpointR == 0.0
    # A wheel's encoder is trusted until a fault of its own, or the driver's, latches.
    trusted_l = not s.faultFlags & FAULTS_UNTRUSTED_L
    trusted_r = not s.faultFlags & FAULTS_UNTRUSTED_R
    braked = ((not trusted_l or abs(s.filtVelL) < C.BRAKE_DONE_SPEED)
              and (not trusted_r or abs(s.filtVelR) < C.BRAKE_DONE_SPEED))
    # Once the hold is on, the chair stays parked while at rest: the hold keeps it there.
    # A fault that leaves no encoder trusted parks at once, at duty 0. With a brake, the
    # chair stays parked until the brake has let go.
    # In push mode the chair stays parked at rest however fast it is pushed: the motors
    # freewheel (``motors``) rather than the PID braking it.
    pushing = bool(s.inhibitStable & C.INHIBIT_PUSH)
    park = (not trusted_l and not trusted_r) or halt or (at_rest and (s.holding or braked or pushing))
    if s.brakeFitted:
        park = brake_step(s, bool(park))
    if park:
        s.parked = 1
        s.integralL = s.integralR = 0.0
        s.prevMeasL = s.filtVelL
        s.prevMeasR = s.filtVelR
        s.outputL = s.outputR = 0.0
    else:
        s.parked = 0
        # A suspect wheel keeps its output: no count is no reason to push harder.
        # beyond the thermal rollback, each within its motor's rolled-back current limit
        if trusted_l and check_l != WHEEL_SUSPECT:
            lo, hi = held_bounds(*pid_bounds(s.windingTempL, s.filtVelL)) if held_l else \
                pid_bounds(s.windingTempL, s.filtVelL)
            s.outputL, s.integralL = compute_pid(s.setpointL, s.filtVelL, s.integralL, s.prevMeasL,
                                                 s.kpL, s.kiL, s.kdL, dt, lo, hi)
            s.prevMeasL = s.filtVelL
        if trusted_r and check_r != WHEEL_SUSPECT:
            lo, hi = held_bounds(*pid_bounds(s.windingTempR, s.filtVelR)) if held_r else \
                pid_bounds(s.windingTempR, s.filtVelR)
            s.outputR, s.integralR = compute_pid(s.setpointR, s.filtVelR, s.integralR, s.prevMeasR,
                                                 s.kpR, s.kiR, s.kdR, dt, lo, hi)
            s.prevMeasR = s.filtVelR
        # after a fault the faulty wheel at duty 0: the driver brakes it whichever way it turns
        if not trusted_l:
            s.outputL = 0.0
        if not trusted_r:
            s.outputR = 0.0
        if s.brakeFitted and s.faultFlags:      # with the brake applied: braking only
            s.outputL = braking_output(s.outputL, s.rawVelL)
            s.outputR = braking_output(s.outputR, s.rawVelR)
    motors(s, delta_l, delta_r, hardest, trusted_l, trusted_r, out)
    # without a brake fitted, the pin is LOW unless the PID drives, and from a fault on
    if not s.brakeFitted:
        s.brakeReleased = 0 if s.parked or s.faultFlags else 1

    pivot_step(s)

    send(s, feedback_line(s), out)
    if s.tlmEnabled:
        send(s, send_telemetry(s, now & 0xFFFFFFFF), out)
    s.errLinesThisTick = 0
