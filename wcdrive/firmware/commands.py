"""Command framing and parsing: ``processByte`` and the parsers of final_control.ino.

A command ends at a line end (``\\n`` or ``\\r``) or at the comma of its last field
(WHEEL and CMDVEL: the 2nd, PPM: the 8th), so the seed host's newline-less
``x:0.500,t:0.100,`` takes effect at the next tick. Malformed commands are counted
and answered with ``ERR:<reason>``; they never change the targets or the mode.
"""

from __future__ import annotations

import functools
import re

from wcdrive.firmware import constants as C
from wcdrive.firmware.avrlibc import strtod
from wcdrive.firmware.f32 import constrain, div, f32, from_int
from wcdrive.firmware.motion import accept_command, emergency_halt
from wcdrive.firmware.output import event_line, reject
from wcdrive.firmware.state import FirmwareState

NEWLINE, RETURN, COMMA = 0x0A, 0x0D, 0x2C
_PPM_PER_US = div(C.PPM_MAX_WHEEL, float(C.PPM_SPAN))


class ParseError(Exception):
    """A malformed command; ``reason`` is the word after ``ERR:``."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def split_fields(buf: bytes, max_fields: int) -> list[bytes] | None:
    """The comma-separated fields (a trailing comma opens none); None when there are
    more than ``max_fields``."""
    fields: list[bytes] = []
    p, end = 0, len(buf)
    while p < end:
        if len(fields) == max_fields:
            return None
        q = buf.find(b",", p)
        if q < 0:
            q = end
        fields.append(buf[p:q])
        p = q + 1
    return fields


def parse_number(field: bytes, start: int, allow_sign: bool, limit: float) -> float:
    c = field[start] if start < len(field) else 0
    digit_or_point = 0x30 <= c <= 0x39 or c == 0x2E
    if not digit_or_point and not (allow_sign and c in (0x2B, 0x2D)):
        raise ParseError("number")
    value, end = strtod(field, start)
    if end == start or end != len(field):
        raise ParseError("number")
    if not (value >= -limit and value <= limit):
        raise ParseError("range")
    return value


def parse_wheel(buf: bytes) -> tuple[int, float, float]:
    """``rp5.0,lp3.0,`` -> (mode, right, left)."""
    f = split_fields(buf, 2)
    if f is None or len(f) != 2:
        raise ParseError("fields")
    if f[0][:1] != b"r" or f[1][:1] != b"l":
        raise ParseError("syntax")
    v = [0.0, 0.0]
    for i in range(2):
        sign = f[i][1:2]
        if sign not in (b"p", b"n"):
            raise ParseError("syntax")
        v[i] = parse_number(f[i], 2, False, C.MAX_WHEEL_SPEED)
        if sign == b"n":
            v[i] = -v[i]
    return C.MODE_WHEEL, v[0], v[1]


def parse_cmd_vel(buf: bytes) -> tuple[int, float, float]:
    """``x:0.5,t:0.1,`` -> (mode, right, left) through the kinematics."""
    f = split_fields(buf, 2)
    if f is None or len(f) != 2:
        raise ParseError("fields")
    if f[0][:2] != b"x:" or f[1][:2] != b"t:":
        raise ParseError("syntax")
    x = parse_number(f[0], 2, True, C.MAX_LINEAR)
    t = parse_number(f[1], 2, True, C.MAX_ANGULAR)
    half_turn = div(f32(t * C.WHEELBASE), 2.0)
    right = div(f32(x + half_turn), C.WHEEL_RADIUS)
    left = div(f32(x - half_turn), C.WHEEL_RADIUS)
    peak = abs(right) if abs(right) > abs(left) else abs(left)
    if peak > C.MAX_WHEEL_SPEED:
        k = div(C.MAX_WHEEL_SPEED, peak)
        right = f32(right * k)
        left = f32(left * k)
    return C.MODE_CMDVEL, right, left


def shape_stick(us: int) -> int:
    if -C.PPM_DEADBAND <= us <= C.PPM_DEADBAND:
        return 0
    return max(-C.PPM_SPAN, min(C.PPM_SPAN, us))


def parse_ppm(buf: bytes) -> tuple[int, float, float] | None:
    """``ppm:c1,...,c8,`` -> (mode, right, left), or None for a frame that says the
    receiver lost the transmitter (a channel outside the valid range)."""
    if buf[3] != 0x3A:
        raise ParseError("syntax")
    f = split_fields(buf[:3] + b"," + buf[4:], C.PPM_CHANNELS + 1)
    if f is None or len(f) != C.PPM_CHANNELS + 1:
        raise ParseError("fields")
    channels = []
    lost = False
    for field in f[1:]:
        if not field or len(field) > 4 or not all(0x30 <= c <= 0x39 for c in field):
            raise ParseError("number")
        value = int(field)
        channels.append(value)
        if value < C.PPM_VALID_MIN or value > C.PPM_VALID_MAX:
            lost = True
    if lost:
        return None
    fwd = f32(from_int(shape_stick(channels[C.PPM_FWD_CHANNEL] - C.PPM_NEUTRAL)) * _PPM_PER_US)
    turn = f32(from_int(shape_stick(channels[C.PPM_TURN_CHANNEL] - C.PPM_NEUTRAL)) * _PPM_PER_US)
    right = constrain(f32(fwd - turn), -C.PPM_MAX_WHEEL, C.PPM_MAX_WHEEL)
    left = constrain(f32(fwd + turn), -C.PPM_MAX_WHEEL, C.PPM_MAX_WHEEL)
    return C.MODE_PPM, right, left


@functools.lru_cache(maxsize=1024)
def parse(buf: bytes) -> tuple[int, float, float] | str | None:
    """A complete command's meaning, which depends on its bytes alone (so hosts that
    repeat a command are parsed once): (mode, right, left), None for a PPM frame that
    signals loss, or the ERR reason."""
    try:
        if any(c <= 0x20 or c >= 0x7F for c in buf):
            raise ParseError("syntax")
        if buf[:1] == b"r":
            return parse_wheel(buf)
        if buf[:1] == b"x":
            return parse_cmd_vel(buf)
        if len(buf) >= 4 and buf[:3] == b"ppm":
            return parse_ppm(buf)
        raise ParseError("syntax")
    except ParseError as error:
        return error.reason


def fields_expected(s: FirmwareState) -> int:
    buf = s.cmdBuf
    if buf[:1] in (b"r", b"x"):
        return 2
    if len(buf) >= 4 and buf[:4] == b"ppm:":
        return C.PPM_CHANNELS
    return 0


def finish_command(s: FirmwareState, out: bytearray) -> None:
    result = parse(bytes(s.cmdBuf))
    if isinstance(result, str):
        reject(s, result, out)
    elif result is None:                       # PPM: signal lost
        s.mode = C.MODE_PPM
        s.cmdSinceTick = 1
        emergency_halt(s)
        if not s.ppmLost:
            out += event_line("PPM_LOST")
        s.ppmLost = 1
    else:
        mode, right, left = result
        if mode == C.MODE_PPM:
            s.ppmLost = 0
        accept_command(s, mode, right, left)
    _reset(s)


def _reset(s: FirmwareState) -> None:
    s.cmdBuf = bytearray()
    s.cmdLen = 0
    s.cmdCommas = 0


def process_byte(s: FirmwareState, c: int, out: bytearray) -> None:
    """One received byte, as ``processByte`` handles it."""
    if c == NEWLINE or c == RETURN:
        if s.cmdDiscarding:
            s.cmdDiscarding = 0
        elif s.cmdLen > 0:
            finish_command(s, out)
        return
    if s.cmdDiscarding:
        if c == COMMA:
            s.cmdDiscarding = 0
        return
    if s.cmdLen >= C.CMD_MAX_LEN:
        reject(s, "overlong", out)
        _reset(s)
        s.cmdDiscarding = 0 if c == COMMA else 1
        return
    s.cmdBuf.append(c)
    s.cmdLen += 1
    if c != COMMA:
        return
    s.cmdCommas += 1
    expected = fields_expected(s)
    if expected == 0:
        reject(s, "syntax", out)
        _reset(s)
    elif s.cmdCommas >= expected:
        finish_command(s, out)


_SPECIAL = re.compile(rb"[,\n\r]")


def process_bytes(s: FirmwareState, data: bytes, out: bytearray) -> None:
    """``process_byte`` over ``data``; runs of ordinary bytes that fit the buffer are
    appended at once (the same result, fewer Python calls)."""
    i, n = 0, len(data)
    while i < n:
        if not s.cmdDiscarding:
            m = _SPECIAL.search(data, i)
            j = m.start() if m else n
            if i < j <= i + C.CMD_MAX_LEN - s.cmdLen:
                s.cmdBuf += data[i:j]
                s.cmdLen += j - i
                i = j
                continue
        process_byte(s, data[i], out)
        i += 1
