"""The control tick of final_control.ino: velocity, filter, watchdog, ramp, parking,
PID with back-calculation anti-windup, motor outputs, pivot and feedback."""

from __future__ import annotations

from wcdrive.avr.f32 import div, f32, from_int
from wcdrive.firmware import constants as C
from wcdrive.firmware.motion import emergency_halt, pivot_step
from wcdrive.firmware.output import feedback_line, send_event, send_telemetry
from wcdrive.firmware.state import FirmwareState

_OUT_MAX = C.PID_OUT_MAX


def compute_pid(setpoint: float, measurement: float, integral: float, prev_meas: float,
                kp: float, ki: float, kd: float, dt: float) -> tuple[float, float]:
    """``computePID``: returns ``(clamped output, new integral)``."""
    error = f32(setpoint - measurement)
    integral = f32(integral + f32(error * dt))
    limit = div(_OUT_MAX, ki)
    # constrain(integral, -limit, limit)
    integral = -limit if integral < -limit else (limit if integral > limit else integral)
    derivative = div(-f32(measurement - prev_meas), dt)
    p_term = f32(kp * error)
    d_term = f32(kd * derivative)
    output = f32(f32(p_term + f32(ki * integral)) + d_term)
    clamped = -_OUT_MAX if output < -_OUT_MAX else (_OUT_MAX if output > _OUT_MAX else output)
    if output != clamped:
        integral = div(f32(f32(clamped - p_term) - d_term), ki)
    return clamped, integral


def ramp_toward(current: float, target: float, max_change: float) -> float:
    """``rampToward``: ``current`` moved toward ``target`` by at most ``max_change``."""
    diff = f32(target - current)
    if abs(diff) <= max_change:
        return target
    return f32(current + (max_change if diff > 0.0 else -max_change))


def set_motor(output: float) -> tuple[int, int]:
    """``setMotor``: ``(pwm duty, dir level)`` for a PID output."""
    direction = C.HIGH if output >= 0.0 else C.LOW
    return int(f32(abs(output) * C.PWM_SCALE)) & 0xFF, direction


def _i32(x: int) -> int:
    return (x + 2**31) % 2**32 - 2**31


def control_tick(s: FirmwareState, now: int, count_l: int, count_r: int, out: bytearray,
                 illegal_l: int = 0, illegal_r: int = 0) -> None:
    """``controlTick(now)`` with the encoder and illegal-transition counts it latches
    atomically."""
    dt = div(from_int((now - s.lastControlTime) & 0xFFFFFFFF), 1000.0)
    s.lastControlTime = now & 0xFFFFFFFF
    s.tickCount = (s.tickCount + 1) & 0xFFFFFFFF

    s.encTickL, s.encTickR = _i32(count_l), _i32(count_r)
    s.illTickL, s.illTickR = illegal_l & 0xFFFFFFFF, illegal_r & 0xFFFFFFFF
    delta_l = _i32(s.encTickL - s.prevEncL)
    delta_r = _i32(s.encTickR - s.prevEncR)
    s.prevEncL, s.prevEncR = s.encTickL, s.encTickR

    per_second = div(C.TWO_PI, dt)
    s.rawVelL = f32(-div(from_int(delta_l), C.CPR) * per_second)
    s.rawVelR = f32(div(from_int(delta_r), C.CPR) * per_second)
    s.filtVelL = f32(f32(C.ALPHA * s.rawVelL) + f32(C.ONE_MINUS_ALPHA * s.filtVelL))
    s.filtVelR = f32(f32(C.ALPHA * s.rawVelR) + f32(C.ONE_MINUS_ALPHA * s.filtVelR))

    if s.cmdSinceTick:
        s.cmdSinceTick = 0
        s.lastCmdTime = now & 0xFFFFFFFF
        s.watchdogArmed = 1
    if s.watchdogArmed and ((now - s.lastCmdTime) & 0xFFFFFFFF) >= s.watchdogMs:
        s.watchdogArmed = 0
        emergency_halt(s)
        out += send_event("WATCHDOG")

    max_change = f32((s.estopDecel if s.emergencyStop else s.maxAccel) * dt)
    s.setpointL = ramp_toward(s.setpointL, s.targetL, max_change)
    s.setpointR = ramp_toward(s.setpointR, s.targetR, max_change)

    still = abs(s.filtVelL) < C.STILL_SPEED and abs(s.filtVelR) < C.STILL_SPEED
    if not still:
        s.stillTicks = 0
    elif s.stillTicks < 255:
        s.stillTicks += 1
    at_rest = s.targetL == 0.0 and s.targetR == 0.0 and s.setpointL == 0.0 and s.setpointR == 0.0
    if at_rest and (s.stillTicks >= C.STILL_TICKS or s.emergencyStop):
        s.parked = 1
        s.integralL = s.integralR = 0.0
        s.prevMeasL = s.filtVelL
        s.prevMeasR = s.filtVelR
        s.outputL = s.outputR = 0.0
    else:
        s.parked = 0
        s.outputL, s.integralL = compute_pid(s.setpointL, s.filtVelL, s.integralL, s.prevMeasL,
                                             s.kpL, s.kiL, s.kdL, dt)
        s.prevMeasL = s.filtVelL
        s.outputR, s.integralR = compute_pid(s.setpointR, s.filtVelR, s.integralR, s.prevMeasR,
                                             s.kpR, s.kiR, s.kdR, dt)
        s.prevMeasR = s.filtVelR
    s.pwmL, s.dirL = set_motor(s.outputL)
    s.pwmR, s.dirR = set_motor(s.outputR)

    pivot_step(s)

    out += feedback_line(s)
    if s.tlmEnabled:
        out += send_telemetry(s, now & 0xFFFFFFFF)
    s.errLinesThisTick = 0
