"""The Eddie board's Position Controllers: ``PositionController.tick(left, right)`` is
one ``PDLoop`` pass, 20 ms (``DIVISOR`` = 50 per second), given the wheels' positions
(forward positive); it returns the motor powers (left, right), -7520..7520
(``MAX_ON_TIME``). Between passes the state is the source's variables, one ``Wheel``
a side, and the ``mode`` the last motion command chose (``MODE_NAMES``).

What it keeps from the source (``PDIteration`` in ``Eddie.spin``, right wheel first):

* integer Spin arithmetic throughout (``spin_arithmetic``);
* the four modes: POWER (the set power, slewed), VELOCITY (the mid position moved
  at the set velocity, its changes of velocity limited by ``max_pos_accel``),
  STOPPING (to a set position, decelerating at the rate ``STOP`` computed), POSITION
  (to a set position at the set velocity, accelerating within ``max_pos_accel``);
* the deadzone as written (``elseif Difference =< DEADZONE`` is taken for every
  difference below 1, so a zero error gives +1), ``Kp`` and the power slew
  ``MAX_ON_TIME / 16``;
* the speed: positions in the last 0.5 s, low byte, times two (the source's
  ``~ToSignExtend * 2``);
* ``DIST`` and ``HEAD``'s values (``distance``, ``heading``) and
  ``InterpolateMidVariables``, which the motion commands call before they change mode.

``tick`` also runs the ``WATCH`` timer (``watch_s``), which is not in this source
(``command_interpreter`` says where it comes from): with no command accepted for
``watch_s`` seconds it sets every power and velocity to 0 in POWER mode.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from wcdrive.eddie.spin_arithmetic import CLKFREQ, clamp, s32, sdiv, smod, ssqrt, sx8, sx16

DIVISOR = 50                       # control loop iterations per second
DEADZONE = 1
MAX_ON_TIME = CLKFREQ // 10_000 - CLKFREQ * 6 // 1_000_000     # 7520
KP = MAX_ON_TIME // 16             # 470
MAX_POW_ACCEL = MAX_ON_TIME // 16  # 470 per iteration
DEFAULT_POS_ACCEL = 200
#: Positions one wheel makes while the robot turns 360 degrees in place (the source's constant).
POSITIONS_PER_ROTATION = 186

#: Position samples the speed spans: 0.5 s of control iterations, and the one before.
HISTORY = DIVISOR // 2 + 1

POWER, VELOCITY, STOPPING, POSITION = range(4)
MODE_NAMES = ("POWER", "VELOCITY", "STOPPING", "POSITION")


@dataclass
class Wheel:
    """One side's Position Controller variables, as the source names them."""

    motor_position: int = 0
    mot_pos_offset: int = 0
    motor_power: int = 0
    mid_position: int = 0
    mid_pos_acc: int = 0
    mid_velocity: int = 0
    mid_vel_acc: int = 0
    set_position: int = 0
    set_velocity: int = 0
    set_power: int = 0
    decel: int = 0
    still_cnt: int = 0
    motor_speed: int = 0
    history: deque[int] = field(default_factory=lambda: deque([0] * HISTORY, maxlen=HISTORY))


class PositionController:
    """Both wheels' Position Controllers and the loop that runs them. ``ticks`` counts
    the passes (the ``WATCH`` timer); ``last_command_tick`` is the pass of the last
    command accepted."""

    def __init__(self) -> None:
        self.wheels = (Wheel(), Wheel())     # LEFT, RIGHT
        self.mode = POWER
        self.max_pos_accel = DEFAULT_POS_ACCEL
        self.watch_s = 0
        self.ticks = 0
        self.last_command_tick = 0

    def _interpolate_mid(self) -> None:
        """``InterpolateMidVariables`` (its right ``MidVelAcc`` is never cleared: kept)."""
        for w in self.wheels:
            diff = sdiv(w.set_power, KP)
            if diff:
                diff = diff - DEADZONE if diff >= DEADZONE else diff + DEADZONE
                w.mid_position = s32(w.motor_position + diff)
            else:
                w.mid_position = w.motor_position
            w.mid_pos_acc = 0
            w.mid_velocity = w.motor_speed
        self.wheels[0].mid_vel_acc = 0

    def distance(self) -> tuple[int, int]:
        """``DIST``'s two values: positions since ``RST``, forward positive."""
        return tuple(s32(w.motor_position + w.mot_pos_offset) for w in self.wheels)  # type: ignore[return-value]

    def heading(self) -> int:
        """``HEAD``'s value: ``((L - R) // 186) * 360 / 186``, negative when L < R."""
        left, right = self.distance()
        return sdiv(smod(s32(left - right), POSITIONS_PER_ROTATION) * 360, POSITIONS_PER_ROTATION)

    # ---- the Position Controller loop ---------------------------------------------
    def tick(self, left_position: int, right_position: int) -> tuple[int, int]:
        """One ``PDLoop`` pass (right wheel first, as the source): reads the Position
        Controllers, returns the motor powers (left, right), -7520..7520."""
        self.ticks += 1
        if self.watch_s and self.ticks - self.last_command_tick > self.watch_s * DIVISOR:
            for w in self.wheels:
                w.set_power = 0
                w.set_velocity = 0
            self.mode = POWER
        right = self._iteration(1, right_position)
        left = self._iteration(0, left_position)
        return left, right

    def _iteration(self, side: int, position: int) -> int:
        w = self.wheels[side]
        w.history.append(position)
        speed_byte = sx8(w.history[-1] - w.history[0])     # positions in the last 0.5 s
        w.motor_speed = speed_byte * 2
        raw = position & 0xFFFF
        w.motor_position = s32(w.motor_position + sx16(raw - w.motor_position))
        if abs(w.motor_speed) <= 2 or raw == 0:
            w.still_cnt = min(w.still_cnt + 1, 127)
        else:
            w.still_cnt = 0
        a = self.max_pos_accel
        if self.mode == POWER:
            w.motor_power += clamp(w.set_power - w.motor_power, -MAX_POW_ACCEL, MAX_POW_ACCEL)
            return w.motor_power
        if self.mode == VELOCITY:
            w.mid_vel_acc += clamp((w.set_velocity - w.mid_velocity) * DIVISOR - w.mid_vel_acc, -a, a)
            w.mid_velocity += sdiv(w.mid_vel_acc, DIVISOR)
            w.mid_vel_acc = smod(w.mid_vel_acc, DIVISOR)
            w.mid_pos_acc += w.mid_velocity
            w.mid_position = s32(w.mid_position + sdiv(w.mid_pos_acc, DIVISOR))
            w.mid_pos_acc = smod(w.mid_pos_acc, DIVISOR)
        elif self.mode == STOPPING:
            limit = sdiv(ssqrt(sdiv(s32(8 * DIVISOR * DIVISOR * (w.set_position - w.mid_position)), w.decel))
                         * w.decel, 2)
            self._approach(w, limit)
        elif self.mode == POSITION:
            w.mid_vel_acc += clamp((w.set_velocity - w.mid_velocity) * DIVISOR - w.mid_vel_acc, -a, a)
            w.mid_velocity += sdiv(w.mid_vel_acc, DIVISOR)
            w.mid_vel_acc = smod(w.mid_vel_acc, DIVISOR)
            ahead = s32(8 * DIVISOR * DIVISOR * (w.set_position - w.mid_position))
            curve = sdiv(ssqrt(sdiv(ahead, a)) * a, 2)
            limit = min(w.mid_velocity * DIVISOR + w.mid_vel_acc, curve)
            self._approach(w, limit)
        else:
            w.motor_power = 0
            return 0
        diff = w.mid_position - w.motor_position
        diff = diff - DEADZONE if diff >= DEADZONE else diff + DEADZONE
        w.set_power = clamp(diff * KP, -MAX_ON_TIME, MAX_ON_TIME)
        w.motor_power += clamp(w.set_power - w.motor_power, -MAX_POW_ACCEL, MAX_POW_ACCEL)
        return w.motor_power

    @staticmethod
    def _approach(w: Wheel, limit: int) -> None:
        scale = DIVISOR * DIVISOR
        w.mid_pos_acc += clamp(s32((w.set_position - w.mid_position) * scale + w.mid_pos_acc), -limit, limit)
        w.mid_position = s32(w.mid_position + sdiv(w.mid_pos_acc, scale))
        w.mid_pos_acc = smod(w.mid_pos_acc, scale)

    @property
    def mode_name(self) -> str:
        """POWER, VELOCITY, STOPPING or POSITION."""
        return MODE_NAMES[self.mode]
