"""The Eddie control board's firmware as a pure, deterministic model.

Derived line by line from Parallax's Spin source of the Eddie control board firmware
(``Eddie.spin``, Propeller Tool archive of 2011-12-19, VERSION 12 before a third
party's +100; public at github.com/robotictang/eddiebot_firmware) and its motor
driver (``Eddie Motor Driver.spin``). No Propeller emulator was built: this is a port
by reading, and docs/eddie.md lists what the source leaves open.

What it keeps from the source:

* the line buffer (255 bytes, ``BUFFER_LENGTH``): bytes are stored until CR; BS
  removes itself and the byte before; a bare CR gets no answer at all; the 255th byte
  without a CR answers ``ERROR`` once the next CR arrives, and that line is dropped;
  control characters (LF among them) are *stored*, as the source's empty ``case``
  branch does, so ``eol="firmware"`` makes ``"DIST\\r\\n"`` poison the next command.
  ``eol="tolerant"`` is the issue's reading instead: LF ends a line, and an LF right
  after a CR is dropped (docs/eddie.md says why both exist);
* the parser: the command is the text before the first space or tab, upper-cased;
  parameters are 1 to 8 hexadecimal digits (either case), read in order, each
  checked before the next is looked for; errors answer ``ERROR`` (``ERROR - <reason>``
  after ``VERB 1``) and change nothing;
* sign handling exactly as the source does it: ``GO`` sign-extends the low byte
  (``~``), ``GOSPD``/``TRVL``/``TURN`` the low word (``~~``), so ``FFFFFF9C`` and
  ``FF9C`` are both -100 and ``80000000`` is 0; ``STOP`` and ``ACC`` take all 32 bits;
* replies at fixed widths, upper-case, two's complement: ``DIST`` 8+8 digits, ``SPD``
  4+4, ``HEAD`` 3, ``VER``/``HWVER`` 4, ``ADC`` 8 x 3, ``PING`` 3 per PING))) pin,
  GPIO masks 8;
* the Position Controller loop (``PDIteration``) at 50 Hz, integer Spin arithmetic
  (division truncating toward zero, ``//`` with the dividend's sign, ``^^`` the square
  root of the unsigned 32-bit value), the four modes (POWER, VELOCITY, STOPPING,
  POSITION), the deadzone as written (``elseif Difference =< DEADZONE`` is taken for
  every difference below 1, so a zero error gives +1), ``Kp`` and the power slew
  ``MAX_ON_TIME / 16``;
* the Position Controllers' speed: positions in the last 0.5 s, low byte, times two
  (the source's ``~ToSignExtend * 2``).

``WATCH`` is not in this source (it is in the seed's Table 1): it is modelled as a
later firmware has it (docs/eddie.md): ``WATCH 0`` off (the default), ``WATCH n``
(1..1A) stops the motors when no command was accepted for ``n`` s.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from wcdrive.errors import WcdriveError

CLKFREQ = 80_000_000
BUFFER_LENGTH = 255
VERSION = 12
DIVISOR = 50                       # control loop iterations per second
DEADZONE = 1
MAX_ON_TIME = CLKFREQ // 10_000 - CLKFREQ * 6 // 1_000_000     # 7520
KP = MAX_ON_TIME // 16             # 470
MAX_POW_ACCEL = MAX_ON_TIME // 16  # 470 per iteration
DEFAULT_POS_ACCEL = 200
#: Positions one wheel makes while the robot turns 360 degrees in place (the source's constant).
POSITIONS_PER_ROTATION = 186
OUTPUTABLE = 0x0007FFFF
PINGABLE = 0x0000FFFF
INITIAL_GPIO = (1 << 16) | (1 << 17) | (1 << 18)
INITIAL_PING = 0b1111
MAX_WATCH_SECONDS = 0x1A
#: Ping results are pulse widths in clock cycles; the reply is ``width >> 9``.
PING_SHIFT = 9
PING_MIN, PING_MAX = 18, 2900
#: The main loop's waits: ``PING`` waits 25 ms for the echoes, ``STOP 0`` 20 ms.
PING_WAIT_S = 1.0 / 40
STOP_WAIT_S = 1.0 / DIVISOR

#: Position samples the speed spans: 0.5 s of control iterations, and the one before.
HISTORY = DIVISOR // 2 + 1

POWER, VELOCITY, STOPPING, POSITION = range(4)
MODE_NAMES = ("POWER", "VELOCITY", "STOPPING", "POSITION")

ERR_OVERFLOW = " - Overflow"
ERR_COMMAND = " - Invalid command"
ERR_PARAMETER = " - Invalid parameter"
ERR_FEW = " - Too few parameters"
ERR_MANY = " - Too many parameters"
ERR_ENCODER = " - Encoder error"

CR, LF, BS, HT = 0x0D, 0x0A, 0x08, 0x09


def s32(v: int) -> int:
    """Wraps to a signed 32-bit long, as every Spin variable is."""
    v &= 0xFFFFFFFF
    return v - (1 << 32) if v & 0x80000000 else v


def sx8(v: int) -> int:
    """Spin's ``~``: sign-extend bit 7."""
    v &= 0xFF
    return v - 0x100 if v & 0x80 else v


def sx16(v: int) -> int:
    """Spin's ``~~``: sign-extend bit 15."""
    v &= 0xFFFF
    return v - (1 << 16) if v & 0x8000 else v


def sdiv(a: int, b: int) -> int:
    """Spin's ``/``: truncates toward zero. Division by zero gives 0 here (the source
    never guards it; docs/eddie.md)."""
    if b == 0:
        return 0
    q = abs(a) // abs(b)
    return s32(q if (a >= 0) == (b >= 0) else -q)


def smod(a: int, b: int) -> int:
    """Spin's ``//``: the remainder, with the sign of the dividend."""
    if b == 0:
        return 0
    return s32(a - sdiv(a, b) * b)


def ssqrt(a: int) -> int:
    """Spin's ``^^``: integer square root of the value read as unsigned 32-bit."""
    return math.isqrt(a & 0xFFFFFFFF)


def clamp(v: int, lo: int, hi: int) -> int:
    """``lo #> v <# hi``."""
    return min(max(v, lo), hi)


def hexw(value: int, digits: int) -> bytes:
    """``OutputHex``: the low ``digits`` nibbles, upper case."""
    return f"{value & ((1 << (4 * digits)) - 1):0{digits}X}".encode()


class ParseError(WcdriveError):
    """A Spin ``abort`` with one of the source's reason strings."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


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


@dataclass
class EddieInputs:
    """What the board reads from its pins: ``ping_m`` the distance each PING))) pin's
    sensor sees (m, None: no echo), ``adc`` the eight 12-bit conversions, ``ina`` the
    GPIO input levels."""

    ping_m: dict[int, float | None] = field(default_factory=dict)
    adc: list[int] = field(default_factory=lambda: [0] * 8)
    ina: int = 0


class EddieFirmware:
    """The board: ``feed(data)`` takes received bytes and returns the reply bytes;
    ``tick(left, right)`` is one 20 ms Position Controller iteration given the wheels'
    positions (forward positive), returning the motor powers (-7520..7520).
    ``ticks`` counts them (the ``WATCH`` timer)."""

    def __init__(self, *, eol: str = "firmware", hw_version: int = 0x0001, version: int = VERSION,
                 speed_of_sound: float = 343.0) -> None:
        if eol not in ("firmware", "tolerant"):
            raise ValueError("eol must be 'firmware' or 'tolerant'")
        self.eol = eol
        self.hw_version = hw_version
        self.version = version
        self.speed_of_sound = speed_of_sound
        self.wheels = (Wheel(), Wheel())     # LEFT, RIGHT
        self.mode = POWER
        self.max_pos_accel = DEFAULT_POS_ACCEL
        self.verbose = 0
        self.gpio_mask = INITIAL_GPIO
        self.ping_mask = INITIAL_PING
        self.dira = 0
        self.outa = 0
        self.blink: tuple[int, int] | None = None
        self.pd_running = True
        self.watch_s = 0
        self.ticks = 0
        self.last_command_tick = 0
        self.inputs = EddieInputs()
        #: How long the last command kept the board's main loop (set by ``PING`` and
        #: ``STOP 0``; the caller holds the reply and the next bytes that long).
        self.busy_s = 0.0
        self._buf = bytearray()
        self._overflow = False
        self._last_cr = False

    # ---- serial side ---------------------------------------------------------------
    def feed(self, data: bytes) -> bytes:
        """Received bytes in; the board's replies out (in order)."""
        out = bytearray()
        for byte in data:
            out += self._byte(byte)
        return bytes(out)

    def _byte(self, b: int) -> bytes:
        after_cr, self._last_cr = self._last_cr, b == CR
        if self._overflow:                  # the source's inner loop: wait for CR (or NUL)
            if b in (CR, 0):
                self._overflow = False
                self._buf.clear()
                return b"ERROR" + (ERR_OVERFLOW.encode() if self.verbose else b"") + b"\r"
            return b""
        if self.eol == "tolerant" and b == LF:
            if after_cr:
                return b""
            b = CR
            self._last_cr = False
        self._buf.append(b)
        if len(self._buf) == BUFFER_LENGTH:
            self._overflow = True
            return b""
        if b == BS:
            self._buf.pop()
            if self._buf:
                self._buf.pop()
            return b""
        if b == CR:
            line = bytes(self._buf[:-1])
            self._buf.clear()
            if not line:
                return b""                  # an empty line: no answer
            return self.execute(line) + b"\r"
        return b""

    def execute(self, line: bytes) -> bytes:
        """One command line (without its CR): the reply without its CR."""
        self.busy_s = 0.0
        try:
            return self._parse(line)
        except ParseError as exc:
            return b"ERROR" + (exc.reason.encode() if self.verbose else b"")

    # ---- the parser -------------------------------------------------------------------
    def _parse(self, line: bytes) -> bytes:
        cut = len(line)
        for i, c in enumerate(line):
            if c in (0x20, HT):
                cut = i
                break
        cmd = line[:cut].upper()
        tokens = [t for t in line[cut:].replace(b"\t", b" ").split(b" ") if t]
        self._tokens = tokens
        handler = _COMMANDS.get(cmd)
        if handler is None:
            raise ParseError(ERR_COMMAND)
        reply = handler(self)
        self.last_command_tick = self.ticks
        return reply

    def _hex(self) -> int:
        """``ParseHex(NextParameter)``: the next parameter as an unsigned 32-bit value."""
        if not self._tokens:
            raise ParseError(ERR_FEW)
        token = self._tokens.pop(0)
        if len(token) > 8 or any(chr(c) not in "0123456789abcdefABCDEF" for c in token):
            raise ParseError(ERR_PARAMETER)
        return s32(int(token, 16))

    def _last(self) -> None:
        """``CheckLastParameter``."""
        if self._tokens:
            raise ParseError(ERR_MANY)

    def _need_pd(self) -> None:
        if not self.pd_running:
            raise ParseError(ERR_ENCODER)

    # interface
    def _c_hwver(self) -> bytes:
        self._last()
        return hexw(self.hw_version, 4)

    def _c_ver(self) -> bytes:
        self._last()
        return hexw(self.version, 4)

    def _c_verb(self) -> bytes:
        p = self._hex()
        self._last()
        if p not in (0, 1):
            raise ParseError(ERR_PARAMETER)
        self.verbose = p
        return b""

    def _c_watch(self) -> bytes:
        p = self._hex()
        self._last()
        if not 0 <= p <= MAX_WATCH_SECONDS:
            raise ParseError(ERR_PARAMETER)
        self.watch_s = p
        return b""

    def _c_blnk(self) -> bytes:
        pin = self._hex()
        rate = self._hex()
        self._last()
        mask = (1 << (pin & 31))
        if mask & OUTPUTABLE:
            if rate:
                if mask & self.ping_mask:
                    # the source passes the pin *number* here, not its mask (kept)
                    self._reset_ping(self.ping_mask & ~pin)
                self.gpio_mask &= ~mask
                self.outa &= ~mask
                self.dira |= mask
                self.blink = (pin & 31, rate & 0xFFFFFFFF)
            else:
                self.blink = None
        return b""

    # I/O
    def _c_out(self) -> bytes:
        p = self._hex()
        self._last()
        self.dira |= p & self.gpio_mask
        return b""

    def _c_in(self) -> bytes:
        p = self._hex()
        self._last()
        self.dira &= ~(p & self.gpio_mask)
        return b""

    def _c_high(self) -> bytes:
        p = self._hex()
        self._last()
        self.outa |= p & self.gpio_mask
        return b""

    def _c_low(self) -> bytes:
        p = self._hex()
        self._last()
        self.outa &= ~(p & self.gpio_mask)
        return b""

    def _c_outs(self) -> bytes:
        self._last()
        return hexw(self.dira & self.gpio_mask, 8)

    def _c_ins(self) -> bytes:
        self._last()
        return hexw(~self.dira & self.gpio_mask, 8)

    def _c_highs(self) -> bytes:
        self._last()
        return hexw(self.outa & self.gpio_mask, 8)

    def _c_lows(self) -> bytes:
        self._last()
        return hexw(~self.outa & self.gpio_mask, 8)

    def ina(self) -> int:
        """The pins' levels: outputs read what they drive, inputs what ``inputs.ina`` says."""
        return (self.outa & self.dira) | (self.inputs.ina & ~self.dira)

    def _c_read(self) -> bytes:
        self._last()
        return hexw(self.ina() & self.gpio_mask, 8)

    # sensors
    def _c_adc(self) -> bytes:
        self._last()
        return b" ".join(hexw(v, 3) for v in self.inputs.adc[:8])

    def ping_value(self, pin: int) -> int:
        """One PING))) pin's reply value: the echo's round trip in clock cycles >> 9,
        0 outside 18..2900 (no echo, too near, too far)."""
        distance = self.inputs.ping_m.get(pin)
        if distance is None:
            return 0
        width = int(2.0 * distance / self.speed_of_sound * CLKFREQ)
        value = width >> PING_SHIFT
        return value if PING_MIN <= value <= PING_MAX else 0

    def _c_ping(self) -> bytes:
        self._last()
        if self.ping_mask:
            self.busy_s = PING_WAIT_S               # ProcessPings: waitcnt(clkfreq / 40)
        values = [hexw(self.ping_value(pin), 3) for pin in range(32) if self.ping_mask >> pin & 1]
        return b" ".join(values)

    def _reset_ping(self, new_mask: int) -> None:
        self.ping_mask = new_mask & PINGABLE
        self.gpio_mask &= ~self.ping_mask

    def _c_sgp(self) -> bytes:
        p = self._hex() & OUTPUTABLE
        self._last()
        if p & self.ping_mask:
            self._reset_ping(self.ping_mask & ~p)
        self.gpio_mask = p
        return b""

    def _c_spng(self) -> bytes:
        p = self._hex() & PINGABLE
        self._last()
        self.gpio_mask &= ~p
        self.outa &= ~p
        self.dira &= ~p
        self._reset_ping(p)
        return b""

    # motion
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

    def _c_go(self) -> bytes:
        left = self._hex()
        right = self._hex()
        self._last()
        self._need_pd()
        self.mode = POWER
        self.wheels[0].set_power = sdiv(sx8(left) * MAX_ON_TIME, 127)
        self.wheels[1].set_power = sdiv(sx8(right) * MAX_ON_TIME, 127)
        return b""

    def _c_gospd(self) -> bytes:
        left = self._hex()
        right = self._hex()
        self._last()
        self._need_pd()
        self._interpolate_mid()
        self.wheels[0].set_velocity = sx16(left)
        self.wheels[1].set_velocity = sx16(right)
        for w in self.wheels:
            w.still_cnt = 0
        self.mode = VELOCITY
        return b""

    def _c_stop(self) -> bytes:
        p = self._hex()
        self._last()
        if not self.pd_running:
            raise ParseError(ERR_ENCODER)
        if p:
            self._interpolate_mid()
            for w in self.wheels:
                if w.set_power < 0:
                    w.set_position = s32(w.motor_position - p)
                elif w.set_power > 0:
                    w.set_position = s32(w.motor_position + p)
                else:
                    w.set_position = w.motor_position
                v = w.mid_velocity
                gap = abs(w.set_position - w.motor_position)
                w.decel = abs(sdiv(s32(-25 * v * v), s32(v - DIVISOR * gap)))
                w.still_cnt = 0
            self.mode = STOPPING
        else:
            self.busy_s = STOP_WAIT_S               # waitcnt(clkfreq / DIVISOR) first
            for w in self.wheels:
                w.set_power = 0
                w.still_cnt = 0
            self.mode = POWER
        return b""

    def _move(self, left: int, right: int, speed: int) -> None:
        self._interpolate_mid()
        for w, d in zip(self.wheels, (left, right), strict=True):
            w.set_velocity = speed
            w.set_position = s32(w.mid_position + d)
            w.still_cnt = 0
        self.mode = POSITION

    def _c_trvl(self) -> bytes:
        dist = self._hex()
        speed = self._hex()
        self._last()
        self._need_pd()
        if not 1 <= speed <= 127:
            raise ParseError(ERR_PARAMETER)
        self._move(sx16(dist), sx16(dist), speed)
        return b""

    def _c_turn(self) -> bytes:
        angle = self._hex()
        speed = self._hex()
        self._last()
        self._need_pd()
        if not 1 <= speed <= 127:
            raise ParseError(ERR_PARAMETER)
        half = POSITIONS_PER_ROTATION // 2
        self._move(sdiv(sx16(angle) * half, 360), -sdiv(sx16(angle) * half, 360), speed)
        return b""

    def _c_acc(self) -> bytes:
        p = self._hex()
        self._last()
        if not 0 <= p <= 511:
            raise ParseError(ERR_PARAMETER)
        self.max_pos_accel = p
        return b""

    def _c_spd(self) -> bytes:
        self._last()
        self._need_pd()
        return hexw(self.wheels[0].motor_speed, 4) + b" " + hexw(self.wheels[1].motor_speed, 4)

    def distance(self) -> tuple[int, int]:
        """``DIST``'s two values: positions since ``RST``, forward positive."""
        return tuple(s32(w.motor_position + w.mot_pos_offset) for w in self.wheels)  # type: ignore[return-value]

    def heading(self) -> int:
        """``HEAD``'s value: ``((L - R) // 186) * 360 / 186``, negative when L < R."""
        left, right = self.distance()
        return sdiv(smod(s32(left - right), POSITIONS_PER_ROTATION) * 360, POSITIONS_PER_ROTATION)

    def _c_head(self) -> bytes:
        self._last()
        self._need_pd()
        return hexw(self.heading(), 3)

    def _c_dist(self) -> bytes:
        self._last()
        self._need_pd()
        left, right = self.distance()
        return hexw(left, 8) + b" " + hexw(right, 8)

    def _c_rst(self) -> bytes:
        self._last()
        for w in self.wheels:
            w.mot_pos_offset = s32(-w.motor_position)
        return b""

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


_COMMANDS = {
    b"HWVER": EddieFirmware._c_hwver, b"VER": EddieFirmware._c_ver, b"VERB": EddieFirmware._c_verb,
    b"WATCH": EddieFirmware._c_watch, b"BLNK": EddieFirmware._c_blnk,
    b"IN": EddieFirmware._c_in, b"OUT": EddieFirmware._c_out, b"LOW": EddieFirmware._c_low,
    b"HIGH": EddieFirmware._c_high, b"INS": EddieFirmware._c_ins, b"OUTS": EddieFirmware._c_outs,
    b"LOWS": EddieFirmware._c_lows, b"HIGHS": EddieFirmware._c_highs, b"READ": EddieFirmware._c_read,
    b"SPNG": EddieFirmware._c_spng, b"SGP": EddieFirmware._c_sgp, b"PING": EddieFirmware._c_ping,
    b"ADC": EddieFirmware._c_adc,
    b"GO": EddieFirmware._c_go, b"GOSPD": EddieFirmware._c_gospd, b"STOP": EddieFirmware._c_stop,
    b"TRVL": EddieFirmware._c_trvl, b"TURN": EddieFirmware._c_turn, b"ACC": EddieFirmware._c_acc,
    b"SPD": EddieFirmware._c_spd, b"HEAD": EddieFirmware._c_head, b"DIST": EddieFirmware._c_dist,
    b"RST": EddieFirmware._c_rst,
}
