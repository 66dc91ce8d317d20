"""The motor outputs of final_control.ino: ``setMotor`` of the PID's output, and the hill
hold (``holdError``, ``holdDuty``, ``holdMotor``): parked, each wheel whose encoder is
trusted is driven back toward the count it came to rest at (protocol/PROTOCOL.md, "Hold
and rollaway"); a fitted brake that holds leaves the motors unpowered
(``wcdrive.firmware.brake``)."""

from __future__ import annotations

from wcdrive.avr.f32 import mul, to_int_trunc
from wcdrive.firmware import constants as C
from wcdrive.firmware.brake import brake_holds
from wcdrive.firmware.output import send, send_event
from wcdrive.firmware.state import FirmwareState

__all__ = ["hold_duty", "hold_error", "hold_motor", "i32", "motors", "push_motor", "set_motor"]


def set_motor(output: float) -> tuple[int, int]:
    """``setMotor``: ``(pwm duty, dir level)`` for a PID output."""
    direction = C.HIGH if output >= 0.0 else C.LOW
    return to_int_trunc(mul(abs(output), C.PWM_SCALE)) & 0xFF, direction


def i32(x: int) -> int:
    """``x`` as an int32_t (two's complement wrap)."""
    return (x + 2**31) % 2**32 - 2**31


def hold_error(count: int, delta: int, ref: int, step: int) -> tuple[int, int, int]:
    """``holdError``: ``(count error, reference, step)``. The reference follows a wheel
    that still slows (a step of the same sign as the last and no larger), then stays, and
    is never more than ROLLAWAY_COUNTS + 1 behind the wheel (pushed farther, the chair is
    braked, not driven back)."""
    if step != 0:
        slowing = delta != 0 and (delta > 0) == (step > 0) and (delta <= step if delta > 0 else delta >= step)
        if slowing:
            ref, step = count, delta
        else:
            step = 0
    error = i32(count - ref)
    most = C.ROLLAWAY_COUNTS + 1
    if abs(error) > most:
        error = most if error > 0 else -most
        ref = i32(count - error)
    return error, ref, step


def hold_duty(error: int, rollaway: int) -> int:
    """``holdDuty``: HOLD_GAIN per count of ``error`` beyond HOLD_DEADBAND_COUNTS, at most
    HOLD_PWM_MAX; after a rollaway (``holdRollaway``), HOLD_PWM_MAX beyond the deadband."""
    size = abs(error)
    if size <= C.HOLD_DEADBAND_COUNTS:
        return 0
    over = size - C.HOLD_DEADBAND_COUNTS
    if rollaway or over >= C.HOLD_PWM_MAX // C.HOLD_GAIN:
        return C.HOLD_PWM_MAX
    return over * C.HOLD_GAIN


def hold_motor(error: int, ahead_dir: int, rollaway: int) -> tuple[int, int]:
    """``holdMotor``: ``(duty, DIR)`` of a held wheel; ``ahead_dir`` turns it back when its
    count ran ahead of the reference. At duty 0, DIR HIGH (``set_motor(0.0)``)."""
    duty = hold_duty(error, rollaway)
    if duty == 0:
        return 0, C.HIGH
    if error > 0:
        return duty, ahead_dir
    return duty, C.LOW if ahead_dir == C.HIGH else C.HIGH


def push_motor(trusted: bool, vel: float) -> tuple[int, int]:
    """``pushMotor``: ``(duty, DIR)`` of a wheel in push mode (the brake released by
    hand): trusted and slower than PUSH_SPEED, the duty its back-EMF takes the way it
    turns (no current, no torque: freewheeling); faster, or not trusted, duty 0 (the
    motor shorted, braking it)."""
    speed = abs(vel)
    if not trusted or speed > C.PUSH_SPEED:
        return 0, C.HIGH
    return to_int_trunc(mul(speed, C.FAULT_EFFORT_EMF)) & 0xFF, C.HIGH if vel >= 0.0 else C.LOW


def motors(s: FirmwareState, delta_l: int, delta_r: int, hardest: bool, trusted_l: bool, trusted_r: bool,
            out: bytearray) -> None:
    """Both motors' duty and DIR: parked, the hold's for each wheel whose encoder is
    trusted (both without a fault; after one, the healthy wheel, and the faulty one
    mirrors it, open loop: the same duty against the same motion; ``holding``;
    ``EVT:ROLLAWAY`` once per hold when a held wheel is pushed ROLLAWAY_COUNTS off its
    reference, and from then on HOLD_PWM_MAX beyond the deadband); parked in push mode,
    ``push_motor`` of each (no hold); else ``set_motor`` of the outputs."""
    if s.parked and s.inhibitStable & C.INHIBIT_PUSH:
        s.pwmL, s.dirL = push_motor(trusted_l, s.filtVelL)
        s.pwmR, s.dirR = push_motor(trusted_r, s.filtVelR)
        s.holding = 0
        return
    held_l = bool(s.parked) and trusted_l
    held_r = bool(s.parked) and trusted_r
    if not (held_l or held_r):
        s.pwmL, s.dirL = set_motor(s.outputL)
        s.pwmR, s.dirR = set_motor(s.outputR)
        s.holding = 0
        return
    if not s.holding:
        s.holdRefL, s.holdRefR = s.encTickL, s.encTickR
        s.holdStepL, s.holdStepR = delta_l, delta_r
        s.holdRollaway = 0
    if hardest:
        s.holdRollaway = 1
    err_l = err_r = 0
    if held_l:
        err_l, s.holdRefL, s.holdStepL = hold_error(s.encTickL, delta_l, s.holdRefL, s.holdStepL)
    if held_r:
        err_r, s.holdRefR, s.holdStepR = hold_error(s.encTickR, delta_r, s.holdRefR, s.holdStepR)
    if (abs(err_l) > C.ROLLAWAY_COUNTS or abs(err_r) > C.ROLLAWAY_COUNTS) and not s.holdRollaway:
        s.holdRollaway = 1
        send(s, send_event("ROLLAWAY"), out)
    if brake_holds(s):                  # the brake holds: the motors unpowered
        err_l = err_r = 0
    s.pwmL, s.dirL = hold_motor(err_l if held_l else -err_r, C.HIGH, s.holdRollaway)
    s.pwmR, s.dirR = hold_motor(err_r if held_r else -err_l, C.LOW, s.holdRollaway)
    s.holding = 1
