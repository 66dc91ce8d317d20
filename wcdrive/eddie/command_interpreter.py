"""The Eddie board's command interpreter: ``CommandInterpreter.execute(line)`` answers
one command line (without its CR) with the reply (without its CR); a line it rejects
answers ``ERROR`` (``ERROR - <reason>`` after ``VERB 1``) and changes nothing. Besides
the Position Controllers it is built on, it holds what the commands set and read: the
GPIO and PING))) masks and the pins' directions and levels, ``inputs`` (what the pins
read), ``verbose``, the ``WATCH`` time, and ``busy_s``.

What it keeps from the source (``Eddie.spin``):

* the parser: the command is the text before the first space or tab, upper-cased;
  parameters are 1 to 8 hexadecimal digits (either case), read in order, each
  checked before the next is looked for; errors answer ``ERROR`` (``ERROR - <reason>``
  after ``VERB 1``) and change nothing;
* sign handling exactly as the source does it: ``GO`` sign-extends the low byte
  (``~``), ``GOSPD``/``TRVL``/``TURN`` the low word (``~~``), so ``FFFFFF9C`` and
  ``FF9C`` are both -100 and ``80000000`` is 0; ``STOP`` and ``ACC`` take all 32 bits;
* replies at fixed widths, upper-case, two's complement: ``DIST`` 8+8 digits, ``SPD``
  4+4, ``HEAD`` 3, ``VER``/``HWVER`` 4, ``ADC`` 8 x 3, ``PING`` 3 per PING))) pin,
  GPIO masks 8.

``WATCH`` is not in this source (it is in the seed's Table 1): it is modelled as a
later firmware has it (docs/eddie.md): ``WATCH 0`` off (the default), ``WATCH n``
(1..1A) stops the motors when no command was accepted for ``n`` s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from wcdrive.eddie.position_controller import (
    DIVISOR,
    MAX_ON_TIME,
    POSITION,
    POSITIONS_PER_ROTATION,
    POWER,
    STOPPING,
    VELOCITY,
    PositionController,
)
from wcdrive.eddie.spin_arithmetic import CLKFREQ, hexw, s32, sdiv, sx8, sx16
from wcdrive.errors import WcdriveError

VERSION = 12
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

ERR_OVERFLOW = " - Overflow"
ERR_COMMAND = " - Invalid command"
ERR_PARAMETER = " - Invalid parameter"
ERR_FEW = " - Too few parameters"
ERR_MANY = " - Too many parameters"
ERR_ENCODER = " - Encoder error"

HT = 0x09


class ParseError(WcdriveError):
    """A Spin ``abort`` with one of the source's reason strings."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass
class EddieInputs:
    """What the board reads from its pins: ``ping_m`` the distance each PING))) pin's
    sensor sees (m, None: no echo), ``adc`` the eight 12-bit conversions, ``ina`` the
    GPIO input levels."""

    ping_m: dict[int, float | None] = field(default_factory=dict)
    adc: list[int] = field(default_factory=lambda: [0] * 8)
    ina: int = 0


class CommandInterpreter(PositionController):
    """The commands of the board and the state they keep, on its Position Controllers:
    ``execute(line)`` runs one command line."""

    def __init__(self, *, hw_version: int, version: int, speed_of_sound: float) -> None:
        super().__init__()
        self.hw_version = hw_version
        self.version = version
        self.speed_of_sound = speed_of_sound
        self.verbose = 0
        self.gpio_mask = INITIAL_GPIO
        self.ping_mask = INITIAL_PING
        self.dira = 0
        self.outa = 0
        self.blink: tuple[int, int] | None = None
        self.pd_running = True
        self.inputs = EddieInputs()
        #: How long the last command kept the board's main loop (set by ``PING`` and
        #: ``STOP 0``; the caller holds the reply and the next bytes that long).
        self.busy_s = 0.0

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


_COMMANDS = {
    b"HWVER": CommandInterpreter._c_hwver, b"VER": CommandInterpreter._c_ver,
    b"VERB": CommandInterpreter._c_verb, b"WATCH": CommandInterpreter._c_watch,
    b"BLNK": CommandInterpreter._c_blnk,
    b"IN": CommandInterpreter._c_in, b"OUT": CommandInterpreter._c_out, b"LOW": CommandInterpreter._c_low,
    b"HIGH": CommandInterpreter._c_high, b"INS": CommandInterpreter._c_ins,
    b"OUTS": CommandInterpreter._c_outs, b"LOWS": CommandInterpreter._c_lows,
    b"HIGHS": CommandInterpreter._c_highs, b"READ": CommandInterpreter._c_read,
    b"SPNG": CommandInterpreter._c_spng, b"SGP": CommandInterpreter._c_sgp,
    b"PING": CommandInterpreter._c_ping, b"ADC": CommandInterpreter._c_adc,
    b"GO": CommandInterpreter._c_go, b"GOSPD": CommandInterpreter._c_gospd,
    b"STOP": CommandInterpreter._c_stop, b"TRVL": CommandInterpreter._c_trvl,
    b"TURN": CommandInterpreter._c_turn, b"ACC": CommandInterpreter._c_acc,
    b"SPD": CommandInterpreter._c_spd, b"HEAD": CommandInterpreter._c_head,
    b"DIST": CommandInterpreter._c_dist, b"RST": CommandInterpreter._c_rst,
}
