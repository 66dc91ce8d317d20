"""The drive limits as final_control.ino applies them: the sketch's ``rampToward``,
``driveCaps``, ``wheelRate`` and ``rampSetpoints`` (docs/safety.md, "Drive limits").

A drive profile's speeds and ramps are runtime parameters (``fwd_speed``, ``rev_speed``,
``drive_accel``, ``drive_decel``, ``turn_speed``, ``turn_accel``, ``turn_at_speed``),
and the cap of what the host may ask on every command path (WHEEL, CMDVEL, PPM): each
tick, before the inhibit's and the rollbacks' caps, the wheel goals are held to

- the chair's speed (the wheels' mean at the rim) within ``fwd_speed`` forward and
  ``rev_speed`` back;
- its turn rate (the wheels' difference at the rim over the wheelbase) within
  ``turn_speed``, less as the speed nears its top: linearly down to ``turn_at_speed``
  of it at the top speed (DX's "Turning @ Full Speed"); the speed kept, the turn cut.

The setpoints then ramp toward the goals: each wheel at ``drive_accel`` speeding up
and ``drive_decel`` slowing down (divided by WHEEL_RADIUS), ``max_accel`` staying the
ceiling of both, and the turn rate changing at most ``turn_accel``; the emergency ramp
(``estop_decel``) is not the profile's. Each default sits past what the wheels can do,
so that at the defaults a goal passes unchanged and the ramp is ``max_accel``'s, as
before the limits.

Before the caps, in PPM mode (the joystick), the profile's ``tremor_damping`` low-passes
the stick (``damped_targets``): each tick the goals move (1 - ``tremor_damping``) of
the way to the stick's targets, a first-order filter at the tick's 20 Hz that takes the
shake of a hand's tremor (4 to 6 Hz) out of the chair's motion while a held deflection
passes (DX's and R-net's tremor damping). The stick at neutral (both targets 0) is
never damped: a stop starts at once. The host's paths (WHEEL, CMDVEL) are not damped:
a navigation stack's commands are not a hand's.
"""

from __future__ import annotations

from wcdrive.avr.f32 import add, div, mul, neg, sub
from wcdrive.firmware import constants as C
from wcdrive.firmware.state import FirmwareState

__all__ = ["damped_targets", "drive_caps", "ramp_setpoints", "ramp_toward", "wheel_rate"]


def ramp_toward(current: float, target: float, max_change: float) -> float:
    """``rampToward``: ``current`` moved toward ``target`` by at most ``max_change``."""
    diff = sub(target, current)
    if abs(diff) <= max_change:
        return target
    return add(current, max_change if diff > 0.0 else neg(max_change))


def damped_targets(s: FirmwareState) -> tuple[float, float]:
    """``dampedTargets``: the goals of this tick before the caps (``dampedL``/``R``). In
    PPM mode with ``tremor_damping`` set, each goal moves (1 - ``tremor_damping``) of
    the way from where it was to its target; otherwise, and whenever both targets are 0
    (a stop is never damped), the targets themselves."""
    if s.mode != C.MODE_PPM or s.tremorDamping == 0.0 or (s.targetL == 0.0 and s.targetR == 0.0):
        s.dampedL, s.dampedR = s.targetL, s.targetR
    else:
        gain = sub(1.0, s.tremorDamping)
        s.dampedL = add(s.dampedL, mul(gain, sub(s.targetL, s.dampedL)))
        s.dampedR = add(s.dampedR, mul(gain, sub(s.targetR, s.dampedR)))
    return s.dampedL, s.dampedR


def drive_caps(s: FirmwareState, goal_l: float, goal_r: float) -> tuple[float, float]:
    """``driveCaps``: the wheel goals (rad/s) within the speed and turn limits; goals
    within every limit pass as they are."""
    speed = mul(mul(add(goal_r, goal_l), 0.5), C.WHEEL_RADIUS)
    turn = div(mul(sub(goal_r, goal_l), C.WHEEL_RADIUS), C.WHEELBASE)
    top = s.fwdSpeed if speed >= 0.0 else s.revSpeed
    held = speed
    if speed > s.fwdSpeed:
        held = s.fwdSpeed
    elif speed < neg(s.revSpeed):
        held = neg(s.revSpeed)
    # the turn limit falls with the speed, to turn_at_speed of it at the top
    cap = mul(s.turnSpeed, sub(1.0, mul(sub(1.0, s.turnAtSpeed), div(abs(held), top))))
    turned = turn
    if turn > cap:
        turned = cap
    elif turn < neg(cap):
        turned = neg(cap)
    if held == speed and turned == turn:
        return goal_l, goal_r
    half = mul(turned, C.HALF_WHEELBASE)
    return div(sub(held, half), C.WHEEL_RADIUS), div(add(held, half), C.WHEEL_RADIUS)


def wheel_rate(s: FirmwareState, setpoint: float, goal: float) -> float:
    """``wheelRate``: rad/s^2 a wheel's setpoint may move toward ``goal``: drive_accel
    when it speeds up (away from zero), drive_decel otherwise, within max_accel."""
    speeding_up = (goal > setpoint >= 0.0) or (goal < setpoint <= 0.0)
    rate = div(s.driveAccel if speeding_up else s.driveDecel, C.WHEEL_RADIUS)
    return s.maxAccel if s.maxAccel < rate else rate


def ramp_setpoints(s: FirmwareState, goal_l: float, goal_r: float, dt: float) -> None:
    """``rampSetpoints``: both setpoints a tick of ``dt`` s toward their goals: the
    emergency ramp at estop_decel; else each wheel at its ``wheel_rate``, the wheels'
    half difference moving at most turn_accel x HALF_WHEELBASE / WHEEL_RADIUS a second
    (the mean kept)."""
    if s.emergencyStop:
        step = mul(s.estopDecel, dt)
        s.setpointL = ramp_toward(s.setpointL, goal_l, step)
        s.setpointR = ramp_toward(s.setpointR, goal_r, step)
        return
    new_l = ramp_toward(s.setpointL, goal_l, mul(wheel_rate(s, s.setpointL, goal_l), dt))
    new_r = ramp_toward(s.setpointR, goal_r, mul(wheel_rate(s, s.setpointR, goal_r), dt))
    limit = mul(div(mul(s.turnAccel, C.HALF_WHEELBASE), C.WHEEL_RADIUS), dt)
    was = mul(sub(s.setpointR, s.setpointL), 0.5)
    change = sub(mul(sub(new_r, new_l), 0.5), was)
    if change > limit or change < neg(limit):
        mid = mul(add(new_r, new_l), 0.5)
        half = add(was, limit if change > 0.0 else neg(limit))
        new_l, new_r = sub(mid, half), add(mid, half)
    s.setpointL, s.setpointR = new_l, new_r
