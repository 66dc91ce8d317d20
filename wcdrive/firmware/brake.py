"""The parking brake the firmware owns, as the sketch's ``brakeCoilFault`` and
``brakeStep`` (docs/safety.md, "The parking brake").

With ``brake_fitted`` 1 the brake has a phase (``brakePhase``):

* ``BRAKE_RELEASED``: the pin HIGH, the PID drives; parked, the hold brakes the chair
  for BRAKE_ACTIVE_TICKS (the active-braking time), then the pin goes LOW;
* ``BRAKE_ENGAGING``: the pin LOW, the hold (or, after a fault, the PID along the
  emergency ramp) still on, for BRAKE_ENGAGE_TICKS, the brake's engage time;
* ``BRAKE_ENGAGED``: the brake holds; parked, the motors are unpowered (they hold again
  after a rollaway, the brake slipping, or a coil fault);
* ``BRAKE_PRELOAD``: a motion asked for, the hold drives against the brake for
  BRAKE_PRELOAD_TICKS, so that its current is up before the brake lets go;
* ``BRAKE_RELEASING``: the pin HIGH, the hold on, for BRAKE_RELEASE_TICKS; then the
  PID drives, the setpoints ramping from zero.

A fault sets the pin LOW at once, and from then on each setpoint is held no farther its
way than its wheel's measured speed (``braking_setpoint``) and each output must brake
(``braking_output``: nothing that drives a wheel the way it turned over the last tick,
or a wheel that stood): the brake stops the wheels faster than the emergency ramp would,
and the PID may brake with it, never drive against it (its derivative would kick a wheel
the brake stops at once). The brake driver's status pin (a smart switch's open-drain
diagnostic) read LOW for BRAKE_STATUS_TICKS ticks in a row, the pin at one level (a
change of the pin starts the count again), is a coil fault:
``BRAKE_OPEN`` with the pin LOW (the switch flags an open load while off),
``BRAKE_SHORT`` with it HIGH (an overload while on). Without a brake the pin follows the
PID as it always did (``brakeReleased`` set by the tick).
"""

from __future__ import annotations

from wcdrive.firmware import constants as C
from wcdrive.firmware.state import FirmwareState

__all__ = [
    "BRAKE_ENGAGED",
    "BRAKE_ENGAGING",
    "BRAKE_PRELOAD",
    "BRAKE_RELEASED",
    "BRAKE_RELEASING",
    "FAULTS_BRAKE",
    "FAULT_BRAKE_OPEN",
    "FAULT_BRAKE_SHORT",
    "brake_coil_fault",
    "brake_holds",
    "brake_step",
    "braking_output",
    "braking_setpoint",
    "set_brake_fitted",
]

BRAKE_ENGAGED, BRAKE_PRELOAD, BRAKE_RELEASING, BRAKE_RELEASED, BRAKE_ENGAGING = 0, 1, 2, 3, 4
FAULT_BRAKE_OPEN, FAULT_BRAKE_SHORT = 0x200, 0x400
FAULTS_BRAKE = FAULT_BRAKE_OPEN | FAULT_BRAKE_SHORT


def brake_coil_fault(s: FirmwareState) -> int:
    """``brakeCoilFault``: the coil fault that latches this tick, or 0."""
    if not s.brakeFitted or not s.brakeStatusTick:
        s.brakeStatusTicks = 0
        return 0
    s.brakeStatusTicks = (s.brakeStatusTicks + 1) & 0xFF
    if s.brakeStatusTicks < C.BRAKE_STATUS_TICKS:
        return 0
    s.brakeStatusTicks = 0
    return FAULT_BRAKE_SHORT if s.brakeReleased else FAULT_BRAKE_OPEN


def brake_step(s: FirmwareState, park: bool) -> bool:
    """``brakeStep``: the phase for this tick, given whether the chair parks, and
    ``brakeReleased``; returns whether the chair stays parked (as asked, or under the
    hold while the brake lets go)."""
    drive = not park and not s.faultFlags
    was = s.brakeReleased
    phase = s.brakePhase
    if phase == BRAKE_RELEASED:
        if s.faultFlags:
            s.brakePhase, s.brakeTicks = BRAKE_ENGAGING, 0
        elif park:
            s.brakeTicks = (s.brakeTicks + 1) & 0xFF
            if s.brakeTicks >= C.BRAKE_ACTIVE_TICKS:
                s.brakePhase, s.brakeTicks = BRAKE_ENGAGING, 0
        else:
            s.brakeTicks = 0
    elif phase == BRAKE_ENGAGING:
        if drive:
            s.brakePhase, s.brakeTicks = BRAKE_RELEASING, 0
        else:
            s.brakeTicks = (s.brakeTicks + 1) & 0xFF
            if s.brakeTicks >= C.BRAKE_ENGAGE_TICKS:
                s.brakePhase = BRAKE_ENGAGED
    elif phase == BRAKE_ENGAGED:
        if drive:
            s.brakePhase, s.brakeTicks = BRAKE_PRELOAD, 0
    elif phase == BRAKE_PRELOAD:
        if not drive:
            s.brakePhase = BRAKE_ENGAGED
        else:
            s.brakeTicks = (s.brakeTicks + 1) & 0xFF
            if s.brakeTicks >= C.BRAKE_PRELOAD_TICKS:
                s.brakePhase, s.brakeTicks = BRAKE_RELEASING, 0
    elif s.faultFlags:                  # BRAKE_RELEASING
        s.brakePhase, s.brakeTicks = BRAKE_ENGAGING, 0
    elif not drive:
        s.brakePhase, s.brakeTicks = BRAKE_RELEASED, 0
    else:
        s.brakeTicks = (s.brakeTicks + 1) & 0xFF
        if s.brakeTicks >= C.BRAKE_RELEASE_TICKS:
            s.brakePhase, s.brakeTicks = BRAKE_RELEASED, 0
    s.brakeReleased = 1 if s.brakePhase in (BRAKE_RELEASING, BRAKE_RELEASED) else 0
    if s.brakeReleased != was:          # the coil's status counted again at the new level
        s.brakeStatusTicks = 0
    return park or (drive and s.brakePhase != BRAKE_RELEASED)


def brake_holds(s: FirmwareState) -> bool:
    """Whether the hold leaves the motors unpowered: the fitted brake holds, no
    rollaway in this hold and no coil fault."""
    return bool(s.brakeFitted and s.brakePhase == BRAKE_ENGAGED and not s.holdRollaway
                and not s.faultFlags & FAULTS_BRAKE)


def set_brake_fitted(s: FirmwareState, fitted: int) -> None:
    """``set:brake_fitted``: the parameter, and the phase from the pin (released, or
    engaging: a brake just set LOW may not hold yet)."""
    s.brakeFitted = fitted
    s.brakePhase = BRAKE_RELEASED if s.brakeReleased else BRAKE_ENGAGING
    s.brakeTicks = 0
    s.brakeStatusTicks = 0


def braking_output(output: float, measured: float) -> float:
    """``brakingOutput``: ``output`` when it brakes the wheel (against ``measured``, its
    speed over the last tick), else 0: the derivative of a wheel the brake stops at once
    would kick it forward."""
    return output if (output > 0.0 and measured < 0.0) or (output < 0.0 and measured > 0.0) else 0.0


def braking_setpoint(setpoint: float, measured: float) -> float:
    """``brakingSetpoint``: ``setpoint`` no farther its way than ``measured``, and never
    past zero: a PID that runs on it can only brake the wheel (after a fault, with the
    brake applied)."""
    if setpoint > 0.0:
        return 0.0 if measured <= 0.0 else (measured if measured < setpoint else setpoint)
    if setpoint < 0.0:
        return 0.0 if measured >= 0.0 else (measured if measured > setpoint else setpoint)
    return setpoint
