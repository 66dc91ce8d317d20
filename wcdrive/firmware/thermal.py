"""The motors' heat as final_control.ino estimates it, and what it does about it: the
sketch's ``windingLoss``, ``windingStep``, ``updateThermal``, ``rollbackOf``,
``thermalShare``, ``pidBounds`` and ``thermalFault`` (docs/safety.md, "Motor heat").

Each tick, each winding's estimate (``windingTempL``/``R``, deg C) takes one step of a
first-order model: a thermal mass (THERMAL_CAPACITY) heated by its copper loss and
cooled through THERMAL_RESISTANCE toward THERMAL_AMBIENT, where it starts at reset.
The board measures neither current nor temperature, so the loss is worked out from
what it commands and what the encoders measure: the duty that drove the interval that
ended, less the back-EMF of the wheel's speed (THERMAL_EMF a rad/s, the motor's own
constant), within the driver's current limit (FAULT_EFFORT_MAX), THERMAL_LOSS watts a
duty squared.

Above THERMAL_ROLLBACK_TEMP the rollback lowers, linearly to THERMAL_CUTOFF_TEMP, each
motor's current limit (the driving effort the PID may ask, toward THERMAL_EFFORT_MIN;
braking is never limited) and the top speed (the faster wheel toward THERMAL_SHARE_MIN
of ``max_wheel``, the hotter winding's). Copper loss follows the torque, not the speed,
so it is the current limit that cools a motor; the estimate settles where the limit it
sets holds it, near 115.6 deg C. ``EVT:THERMAL,1`` when the rollback starts,
``EVT:THERMAL,0`` when both estimates are back THERMAL_HYSTERESIS below its start; one a
tick, in the slot the wait for neutral uses. At THERMAL_CUTOFF_TEMP a winding's fault
latches (``EVT:FAULT,OVERHEAT_L``/``R``): the chair stops and parks.
"""

from __future__ import annotations

from wcdrive.avr.f32 import add, div, mul, sub
from wcdrive.firmware import constants as C
from wcdrive.firmware.output import send, send_event
from wcdrive.firmware.state import FirmwareState

__all__ = ["FAULT_OVERHEAT_L", "FAULT_OVERHEAT_R", "pid_bounds", "rollback_of", "send_thermal_event",
           "thermal_fault", "thermal_share", "update_thermal", "winding_loss", "winding_step"]

FAULT_OVERHEAT_L, FAULT_OVERHEAT_R = 0x800, 0x1000


def winding_loss(pwm: int, direction: int, vel: float) -> float:
    """``windingLoss``: watts of copper loss of a motor driven at ``pwm`` one way
    (``direction`` HIGH: the way ``vel`` counts positive) while its wheel turns at
    ``vel``."""
    duty = float(pwm) if direction == C.HIGH else -float(pwm)
    effort = sub(duty, mul(C.THERMAL_EMF, vel))
    if effort > C.FAULT_EFFORT_MAX:
        effort = C.FAULT_EFFORT_MAX
    elif effort < -C.FAULT_EFFORT_MAX:
        effort = -C.FAULT_EFFORT_MAX
    return mul(mul(effort, effort), C.THERMAL_LOSS)


def winding_step(temp: float, loss: float, dt: float) -> float:
    """``windingStep``: the estimate ``dt`` seconds on, ``loss`` watts in."""
    cool = div(sub(temp, C.THERMAL_AMBIENT), C.THERMAL_RESISTANCE)
    return add(temp, div(mul(dt, sub(loss, cool)), C.THERMAL_CAPACITY))


def update_thermal(s: FirmwareState, dt: float) -> None:
    """``updateThermal``: both estimates a tick on, from the duty that drove the
    interval that ended and the speed measured at its end; the rollback's start and end,
    their events pending."""
    s.windingTempL = winding_step(s.windingTempL, winding_loss(s.pwmL, s.dirL, s.filtVelL), dt)
    s.windingTempR = winding_step(s.windingTempR, winding_loss(s.pwmR, s.dirR, s.filtVelR), dt)
    hot = s.windingTempL if s.windingTempL > s.windingTempR else s.windingTempR
    if not s.thermalRollback and hot > C.THERMAL_ROLLBACK_TEMP:
        s.thermalRollback = 1
        s.thermalPending |= 1
    elif s.thermalRollback and hot < C.THERMAL_ROLLBACK_END:
        s.thermalRollback = 0
        s.thermalPending |= 2


def rollback_of(temp: float) -> float:
    """``rollbackOf``: how far the rollback has gone at ``temp``: 0 up to
    THERMAL_ROLLBACK_TEMP, 1 from THERMAL_CUTOFF_TEMP, linear between."""
    if temp <= C.THERMAL_ROLLBACK_TEMP:
        return 0.0
    k = div(sub(temp, C.THERMAL_ROLLBACK_TEMP), C.THERMAL_ROLLBACK_SPAN)
    return 1.0 if k >= 1.0 else k


def thermal_share(s: FirmwareState) -> float:
    """``thermalShare``: the top wheel speed the hotter winding allows, of ``max_wheel``."""
    hot = s.windingTempL if s.windingTempL > s.windingTempR else s.windingTempR
    return sub(1.0, mul(rollback_of(hot), C.THERMAL_SHARE_SPAN))


def pid_bounds(temp: float, vel: float) -> tuple[float, float]:
    """``pidBounds``: the PID output's ``(lowest, highest)`` for a motor whose winding is
    at ``temp`` and whose wheel turns at ``vel``: beyond the rollback, an output that
    drives (the way the wheel turns, or from a standstill) asks no more effort than the
    rolled-back current limit; one that brakes is free. Else +-PID_OUT_MAX."""
    k = rollback_of(temp)
    lo, hi = -C.PID_OUT_MAX, C.PID_OUT_MAX
    if k == 0.0:
        return lo, hi
    cap = sub(C.FAULT_EFFORT_MAX, mul(k, C.THERMAL_EFFORT_SPAN))
    emf = mul(C.THERMAL_EMF, vel)
    if vel >= 0.0:
        hi = div(add(emf, cap), C.PWM_SCALE)
        if hi > C.PID_OUT_MAX:
            hi = C.PID_OUT_MAX
    if vel <= 0.0:
        lo = div(sub(emf, cap), C.PWM_SCALE)
        if lo < -C.PID_OUT_MAX:
            lo = -C.PID_OUT_MAX
    return lo, hi


def thermal_fault(s: FirmwareState) -> int:
    """``thermalFault``: the fault bits of the windings at THERMAL_CUTOFF_TEMP or more."""
    return ((FAULT_OVERHEAT_L if s.windingTempL >= C.THERMAL_CUTOFF_TEMP else 0)
            | (FAULT_OVERHEAT_R if s.windingTempR >= C.THERMAL_CUTOFF_TEMP else 0))


def send_thermal_event(s: FirmwareState, out: bytearray) -> None:
    """The lowest pending rollback event: ``EVT:THERMAL,1`` (on), ``EVT:THERMAL,0``."""
    if s.thermalPending & 1:
        s.thermalPending &= 2
        send(s, send_event("THERMAL,1"), out)
    else:
        s.thermalPending = 0
        send(s, send_event("THERMAL,0"), out)
