"""What a command or a stop does to the wheel targets, with the pivot state machine.

On a reversal the pivot first brings the chair to rest (PIVOT_STOPPING: setpoints at
zero and both wheels below PIVOT_START_SPEED), then rotates
it in place for PIVOT_TICKS (PIVOT_ROTATING) so the casters swing round, then applies
the pending command. ``pivot_step`` runs once per control tick, after the outputs.
``require_neutral`` starts a wait for a neutral command, ``confirm_neutral`` runs it a
tick at a time."""

from __future__ import annotations

from wcdrive.avr.f32 import add, div, mul
from wcdrive.firmware import constants as C
from wcdrive.firmware.constants import (
    PIVOT_SPEED,
    PIVOT_START_SPEED,
    PIVOT_THRESHOLD,
    PIVOT_TICKS,
    WHEEL_RADIUS,
)
from wcdrive.firmware.output import send, send_event
from wcdrive.firmware.state import FirmwareState

PIVOT_NONE, PIVOT_STOPPING, PIVOT_ROTATING = 0, 1, 2


def needs_pivot(travel: float, prev_travel: float) -> bool:
    """``needsPivot``: the travel (m/s) goes from above PIVOT_THRESHOLD to below
    -PIVOT_THRESHOLD, or back."""
    return (prev_travel > PIVOT_THRESHOLD and travel < -PIVOT_THRESHOLD) or (
        prev_travel < -PIVOT_THRESHOLD and travel > PIVOT_THRESHOLD
    )


def emergency_halt(s: FirmwareState) -> None:
    """Targets to zero; the ramp brings the setpoints down at the emergency rate and the
    PID brakes along it, its integrators started from zero (what they held to keep the
    chair rolling would push against the brake). What they held, and the setpoints then,
    are kept for a command that drives on during the ramp (``resumed_integral``)."""
    if not s.emergencyStop:
        s.haltIntegralL, s.haltIntegralR = s.integralL, s.integralR
        s.haltSetpointL, s.haltSetpointR = s.setpointL, s.setpointR
        s.integralL = s.integralR = 0.0
    s.targetL = s.targetR = 0.0
    s.pivotPhase = PIVOT_NONE
    s.pivotTicksLeft = 0
    s.lastTravel = 0.0
    s.emergencyStop = 1


def require_neutral(s: FirmwareState) -> None:
    """``requireNeutral``: motion needs a neutral command first (``needNeutral``): a new
    wait, or the one under way goes on (its refusal announced, its fault count running)."""
    if not s.needNeutral:
        s.notNeutralSent = 0
        s.notNeutralTicks = 0
        s.neutralFault = 0
    s.needNeutral = 1
    s.neutralSeen = 0


def accept_command(s: FirmwareState, new_mode: int, right: float, left: float) -> None:
    """``acceptCommand``: a valid command's wheel targets, through the pivot: a stop
    applies at once (ending a pivot), a reversal starts one with the command pending,
    and during a pivot a command replaces the pending one. One that drives on during
    an emergency ramp takes the integrals back (``resumed_integral``)."""
    s.mode = new_mode
    s.cmdSinceTick = 1
    resuming = s.emergencyStop
    s.emergencyStop = 0
    travel = mul(mul(add(right, left), 0.5), WHEEL_RADIUS)
    if right == 0.0 and left == 0.0:
        s.pivotPhase = PIVOT_NONE
        s.pivotTicksLeft = 0
        s.targetR = s.targetL = 0.0
    elif needs_pivot(travel, s.lastTravel):
        s.pivotPhase = PIVOT_STOPPING
        s.pivotTicksLeft = 0
        s.pendingR = right
        s.pendingL = left
        s.targetR = s.targetL = 0.0
    elif s.pivotPhase != PIVOT_NONE:
        s.pendingR = right
        s.pendingL = left
    else:
        s.targetR = right
        s.targetL = left
        if resuming:
            s.integralL = resumed_integral(s.haltIntegralL, s.haltSetpointL, s.setpointL, left)
            s.integralR = resumed_integral(s.haltIntegralR, s.haltSetpointR, s.setpointR, right)
    s.lastTravel = travel


def resumed_integral(held: float, was: float, setpoint: float, target: float) -> float:
    """``resumedIntegral``: a wheel driven on the way it went when an emergency ramp
    began takes back the integral it held then (``held``, at setpoint ``was``), in the
    share its setpoint kept of ``was``; otherwise 0. Rebuilt from zero while the chair
    still rolls, the duty collapses and the wheel brakes on its own back-EMF."""
    if was == 0.0 or setpoint == 0.0 or (setpoint > 0.0) != (was > 0.0) or (target > 0.0) != (was > 0.0):
        return 0.0
    share = div(setpoint, was)
    return held if share >= 1.0 else mul(held, share)


def pivot_step(s: FirmwareState) -> None:
    """The pivot step of ``controlTick``, after the motor outputs: STOPPING becomes
    ROTATING once both setpoints are zero and both wheels slow; ROTATING applies the
    pending targets after PIVOT_TICKS ticks."""
    slow = abs(s.filtVelL) < PIVOT_START_SPEED and abs(s.filtVelR) < PIVOT_START_SPEED
    if s.pivotPhase == PIVOT_STOPPING and s.setpointL == 0.0 and s.setpointR == 0.0 and slow:
        s.pivotPhase = PIVOT_ROTATING
        s.pivotTicksLeft = PIVOT_TICKS
        s.targetR = PIVOT_SPEED
        s.targetL = -PIVOT_SPEED
    elif s.pivotPhase == PIVOT_ROTATING:
        s.pivotTicksLeft -= 1
        if s.pivotTicksLeft == 0:
            s.pivotPhase = PIVOT_NONE
            s.targetL = s.pendingL
            s.targetR = s.pendingR


def confirm_neutral(s: FirmwareState, out: bytearray) -> None:
    """The wait for neutral, at most one event a tick and none beside ``WATCHDOG`` (the
    output budget's worst tick): the refusal (``EVT:NOT_NEUTRAL``); the neutral command
    stood ``NEUTRAL_TICKS`` ticks, confirmed (``EVT:NEUTRAL`` when something was refused
    meanwhile); refused for ``NEUTRAL_FAULT_TICKS`` ticks without a neutral command, a
    deflected control (``EVT:DEFLECTED``, until neutral)."""
    if s.notNeutralPending:
        s.notNeutralPending = 0
        send(s, send_event("NOT_NEUTRAL"), out)
    elif s.neutralSeen:
        s.neutralTicks = (s.neutralTicks + 1) & 0xFF
        if s.neutralTicks >= C.NEUTRAL_TICKS:
            if s.notNeutralSent:
                send(s, send_event("NEUTRAL"), out)
            s.needNeutral = s.neutralSeen = s.notNeutralSent = s.neutralFault = 0
    elif s.notNeutralSent and not s.neutralFault:
        s.notNeutralTicks = (s.notNeutralTicks + 1) & 0xFF
        if s.notNeutralTicks >= C.NEUTRAL_FAULT_TICKS:
            s.neutralFault = 1
            send(s, send_event("DEFLECTED"), out)
