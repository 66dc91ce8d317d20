"""Command framing and parsing: ``processByte`` and the parsers of final_control.ino.

A command ends at a line end (``\\n`` or ``\\r``) or at the comma of its last field
(WHEEL and CMDVEL: the 2nd, PPM: the 8th), so the seed host's newline-less
``x:0.500,t:0.100,`` takes effect at the next tick. A v3 frame
``$<seq>:<command>*<CCCC>`` (CRC-16/XMODEM) ends at its line end only. Malformed
commands are counted and answered with ``ERR:<reason>`` (``NAK:<seq>,<reason>`` for a
frame); they never change the targets or the mode. After ``hello`` a line that is not
a frame may only make the chair safer (``estop``, a zero velocity in any form, a PPM
loss frame); anything else is ``ERR:unframed``.
"""

from __future__ import annotations

import binascii
import functools
import re

from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.f32 import add, constrain, div, from_int, mul, sub
from wcdrive.errors import WcdriveError
from wcdrive.firmware import constants as C
from wcdrive.firmware.brake import set_brake_fitted
from wcdrive.firmware.eeprom import restore_defaults, save_params
from wcdrive.firmware.inhibit import drive_inhibited
from wcdrive.firmware.motion import accept_command, emergency_halt, require_neutral
from wcdrive.firmware.output import DATA_HELLO, DATA_NONE, DATA_PARAM, answer, reject, send, send_event
from wcdrive.firmware.params import BY_NAME, PARAMS
from wcdrive.firmware.profiles import drive_limit_set, use_profile
from wcdrive.firmware.state import FirmwareState

NEWLINE, RETURN, COMMA, DOLLAR = 0x0A, 0x0D, 0x2C, 0x24
DISCARD_NONE, DISCARD_TO_COMMA, DISCARD_TO_EOL, DISCARD_OVERRUN = 0, 1, 2, 3
_PPM_PER_US = div(C.PPM_MAX_WHEEL, float(C.PPM_SPAN))


class ParseError(WcdriveError):
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


def number_in_reach(field: bytes, start: int) -> None:
    """``numberInReach``, before ``strtod``: at most ``NUMBER_MAX_DIGITS`` digits before
    the exponent (leading zeros count), else ``ParseError("number")``, and at most
    ``NUMBER_MAX_EXP_DIGITS`` exponent digits, else ``ParseError("range")``. A second
    point, junk or no digit at all is left to ``strtod``."""
    n = len(field)

    def char(i: int) -> int:
        return field[i] if i < n else 0

    i = start
    if char(i) in (0x2B, 0x2D):
        i += 1
    digits = 0
    point = False
    while True:
        c = char(i)
        if 0x30 <= c <= 0x39:
            digits += 1
            if digits > C.NUMBER_MAX_DIGITS:
                raise ParseError("number")
        elif c == 0x2E and not point:
            point = True
        else:
            break
        i += 1
    if digits == 0 or char(i) not in (0x45, 0x65):
        return
    i += 1
    if char(i) in (0x2B, 0x2D):
        i += 1
    exp_digits = 0
    while 0x30 <= char(i) <= 0x39:
        exp_digits += 1
        if exp_digits > C.NUMBER_MAX_EXP_DIGITS:
            raise ParseError("range")
        i += 1


def parse_number(field: bytes, start: int, allow_sign: bool) -> float:
    """``parseNumber``: all of ``field[start:]`` through avr-libc's ``strtod``. It must
    start with a digit or a point (or a sign, with ``allow_sign``); else
    ``ParseError("number")``; ``number_in_reach`` bounds its digits and exponent first."""
    c = field[start] if start < len(field) else 0
    digit_or_point = 0x30 <= c <= 0x39 or c == 0x2E
    if not digit_or_point and not (allow_sign and c in (0x2B, 0x2D)):
        raise ParseError("number")
    number_in_reach(field, start)
    value, end = strtod(field, start)
    if end == start or end != len(field):
        raise ParseError("number")
    return value


def parse_bounded(field: bytes, start: int, allow_sign: bool, limit: float) -> float:
    """``parseBounded``: ``parse_number``, then ``ParseError("range")`` unless
    ``-limit <= value <= limit`` (which inf and NaN are not)."""
    value = parse_number(field, start, allow_sign)
    if not (value >= -limit and value <= limit):
        raise ParseError("range")
    return value


def parse_digits(field: bytes, max_digits: int) -> int:
    """``parseDigits``: 1 to ``max_digits`` decimal digits and nothing else, or -1."""
    if not field or len(field) > max_digits or not all(0x30 <= c <= 0x39 for c in field):
        return -1
    return int(field)


def parse_wheel(buf: bytes, max_wheel: float) -> tuple[int, float, float]:
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
        v[i] = parse_bounded(f[i], 2, False, max_wheel)
        if sign == b"n":
            v[i] = -v[i]
    return C.MODE_WHEEL, v[0], v[1]


def parse_cmd_vel(buf: bytes, max_wheel: float) -> tuple[int, float, float]:
    """``x:0.5,t:0.1,`` -> (mode, right, left) through the kinematics."""
    f = split_fields(buf, 2)
    if f is None or len(f) != 2:
        raise ParseError("fields")
    if f[0][:2] != b"x:" or f[1][:2] != b"t:":
        raise ParseError("syntax")
    x = parse_bounded(f[0], 2, True, C.MAX_LINEAR)
    t = parse_bounded(f[1], 2, True, C.MAX_ANGULAR)
    half_turn = div(mul(t, C.WHEELBASE), 2.0)
    right = div(add(x, half_turn), C.WHEEL_RADIUS)
    left = div(sub(x, half_turn), C.WHEEL_RADIUS)
    peak = abs(right) if abs(right) > abs(left) else abs(left)
    if peak > max_wheel:
        k = div(max_wheel, peak)
        right = mul(right, k)
        left = mul(left, k)
    return C.MODE_CMDVEL, right, left


def shape_stick(us: int) -> int:
    """``shapeStick``: a stick's offset from neutral (µs), 0 inside the dead band, else
    clamped to ±PPM_SPAN."""
    if -C.PPM_DEADBAND <= us <= C.PPM_DEADBAND:
        return 0
    return max(-C.PPM_SPAN, min(C.PPM_SPAN, us))


def parse_ppm(buf: bytes, max_wheel: float) -> tuple[int, float, float] | None:
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
        value = parse_digits(field, 4)
        if value < 0:
            raise ParseError("number")
        channels.append(value)
        if value < C.PPM_VALID_MIN or value > C.PPM_VALID_MAX:
            lost = True
    if lost:
        return None
    fwd = mul(from_int(shape_stick(channels[C.PPM_FWD_CHANNEL] - C.PPM_NEUTRAL)), _PPM_PER_US)
    turn = mul(from_int(shape_stick(channels[C.PPM_TURN_CHANNEL] - C.PPM_NEUTRAL)), _PPM_PER_US)
    cap = max_wheel if max_wheel < C.PPM_MAX_WHEEL else C.PPM_MAX_WHEEL
    right = constrain(sub(fwd, turn), -cap, cap)
    left = constrain(add(fwd, turn), -cap, cap)
    return C.MODE_PPM, right, left


def all_printable(body: bytes) -> bool:
    """Printable ASCII without spaces (``allPrintable``)."""
    return not any(c <= 0x20 or c >= 0x7F for c in body)


@functools.lru_cache(maxsize=1024)
def parse(buf: bytes, max_wheel: float = C.MAX_WHEEL_SPEED) -> tuple[int, float, float] | str | None:
    """A motion command's meaning, which depends on its bytes and the ``max_wheel``
    parameter alone (so hosts that repeat a command are parsed once): (mode, right,
    left), None for a PPM frame that signals loss, or the ERR reason."""
    try:
        if not all_printable(buf):
            raise ParseError("syntax")
        if buf[:1] == b"r":
            return parse_wheel(buf, max_wheel)
        if buf[:1] == b"x":
            return parse_cmd_vel(buf, max_wheel)
        if len(buf) >= 4 and buf[:3] == b"ppm":
            return parse_ppm(buf, max_wheel)
        raise ParseError("syntax")
    except ParseError as error:
        return error.reason


def hex_value(c: int) -> int:
    """``hexValue``: the value of an upper-case hex digit, or -1."""
    if 0x30 <= c <= 0x39:
        return c - 0x30
    if 0x41 <= c <= 0x46:
        return c - 0x41 + 10
    return -1


@functools.lru_cache(maxsize=1024)
def unframe(buf: bytes) -> tuple[str | None, int, bytes]:
    """``$<seq>:<command>*<CCCC>`` -> (reason or None, seq or -1, command). The CRC is
    avr-libc's ``_crc_xmodem_update`` over the bytes between ``$`` and ``*``, which is
    ``binascii.crc_hqx(..., 0)``. A sequence number is returned (and taken as the last
    one) only once the CRC is right and the number well formed. Pure, so cached."""
    n = len(buf)
    if n < 6 or buf[n - 5] != 0x2A:
        return "checksum", -1, buf
    sent = 0
    for c in buf[n - 4:]:
        h = hex_value(c)
        if h < 0:
            return "checksum", -1, buf
        sent = (sent << 4) | h
    if binascii.crc_hqx(buf[1:n - 5], 0) != sent:
        return "checksum", -1, buf
    p = 1
    while 0x30 <= buf[p] <= 0x39:
        if p == 6:
            return "syntax", -1, buf
        p += 1
    if p == 1 or buf[p] != 0x3A or int(buf[1:p]) > C.SEQ_MAX:
        return "syntax", -1, buf
    return None, int(buf[1:p]), buf[p + 1:n - 5]


def find_param(name: bytes) -> int:
    """``findParam``: the parameter's index in ``PARAMS``, or -1."""
    return BY_NAME.get(name, -1)


def parse_get(body: bytes) -> tuple[str | None, int]:
    """``parseGet`` of ``get:<name>``: (reason or None, parameter index)."""
    if not all_printable(body):
        return "syntax", 0
    i = find_param(body[4:])
    return ("param", 0) if i < 0 else (None, i)


def parse_set(s: FirmwareState, body: bytes) -> tuple[str | None, int]:
    """``parseSet`` of ``set:<name>=<value>``: sets the parameter when the value is well
    formed and in range; returns (reason or None, parameter index)."""
    if not all_printable(body):
        return "syntax", 0
    eq = body.find(b"=", 4)
    if eq < 0:
        return "syntax", 0
    i = find_param(body[4:eq])
    if i < 0:
        return "param", 0
    p = PARAMS[i]
    text = body[eq + 1:]
    if p.integer:
        ms = parse_digits(text, 4)
        if ms < 0:
            return "number", 0
        if ms < p.low or ms > p.high:
            return "range", 0
        if p.field == "brakeFitted":
            set_brake_fitted(s, ms)
        elif p.field == "profile":
            use_profile(s, ms)
        else:
            setattr(s, p.field, ms)
        return None, i
    try:
        value = parse_number(text, 0, False)
    except ParseError as error:
        return error.reason, 0
    if not (value >= p.low and value <= p.high):
        return "range", 0
    setattr(s, p.field, value)
    drive_limit_set(s, i, value)
    return None, i


def move_to(s: FirmwareState, body: bytes, out: bytearray) -> str | None:
    """A motion command (``parseWheel``/``parseCmdVel``/``parsePpm`` and ``moveTo``):
    the reason it is refused, or None. An unframed line after hello (``unframedLine``)
    may only stop (``refusedUnframed``). With the e-stop latched a stop or a PPM loss
    frame is accepted and changes nothing; a PPM loss frame otherwise halts the chair
    and writes ``EVT:PPM_LOST`` to ``out`` once."""
    result = parse(body, s.maxWheel)
    if isinstance(result, str):
        return result
    if result is None:                       # PPM: signal lost
        if s.estopLatched or s.faultFlags:   # stopped already: changes nothing
            return None
        s.mode = C.MODE_PPM
        s.cmdSinceTick = 1
        emergency_halt(s)
        require_neutral(s)                   # the transmitter back: its stick to neutral first
        if not s.ppmLost:
            send(s, send_event("PPM_LOST"), out)
        s.ppmLost = 1
        return None
    mode, right, left = result
    reason, take = gate_motion(s, right, left)
    if take:
        if mode == C.MODE_PPM:
            s.ppmLost = 0
        accept_command(s, mode, right, left)
    return reason


def gate_motion(s: FirmwareState, right: float, left: float) -> tuple[str | None, bool]:
    """``gateMotion``: the gate of every motion command (WHEEL, CMDVEL, PPM), as
    ``(reason it is refused or None, whether it drives)``. With the e-stop latched or a
    fault a stop is accepted and changes nothing; anything else is refused: unframed
    after hello, the e-stop, a fault, the chair's limit (a stop releases it), an
    inhibit input that stops the chair, the wait for neutral."""
    stop = right == 0.0 and left == 0.0
    if refused_unframed(s, right, left):
        return "unframed", False
    if s.estopLatched:
        return (None if stop else "estop"), False
    if s.faultFlags:
        return (None if stop else "fault"), False
    if s.limitLatched:
        if not stop:
            return "limit", False
        s.limitLatched = 0                   # the host has seen the limit: what it sends next drives
    if not stop and drive_inhibited(s):
        return "inhibit", False
    if refused_not_neutral(s, right, left):
        return "neutral", False
    return None, True


def refused_unframed(s: FirmwareState, right: float, left: float) -> bool:
    """``refusedUnframed``: after hello, an unframed line may only set zero targets."""
    return bool(s.unframedLine) and (right != 0.0 or left != 0.0)


def refused_not_neutral(s: FirmwareState, right: float, left: float) -> bool:
    """``refusedNotNeutral``: while the board waits for neutral (``needNeutral``), a
    motion command is refused and restarts the wait (``EVT:NOT_NEUTRAL``, once a wait,
    sent by the next tick); a neutral one starts the count the tick confirms."""
    if not s.needNeutral:
        return False
    if right != 0.0 or left != 0.0:
        s.neutralSeen = 0
        if not s.notNeutralSent:
            s.notNeutralSent = 1
            s.notNeutralPending = 1
        return True
    if not s.neutralSeen:
        s.neutralSeen = 1
        s.neutralTicks = 0
    s.notNeutralTicks = 0
    return False


def latch_estop(s: FirmwareState, out: bytearray) -> None:
    """``latchEstop``: halts at the emergency rate, disarms the watchdog and latches the
    e-stop; ``EVT:ESTOP`` goes to ``out`` when it was not latched already."""
    emergency_halt(s)
    s.cmdSinceTick = 0
    s.watchdogArmed = 0
    if not s.estopLatched:
        send(s, send_event("ESTOP"), out)
    s.estopLatched = 1


def reset_estop(s: FirmwareState) -> str | None:
    """``resetEstop``: releases the e-stop and any fault once the chair has parked (after
    a fault, the hold restarts from where both wheels are), and (``unmaskEncoders``)
    clears the ISRs' storm flags: a masked encoder counts again."""
    if (s.estopLatched or s.faultFlags) and not s.parked:
        return "busy"
    if s.estopLatched or s.faultFlags:
        require_neutral(s)   # released: the control must come to neutral before motion
    s.inhibitLatched &= s.inhibitStable   # a latched inhibit whose input is released ends (next tick)
    s.estopLatched = 0
    if s.faultFlags:
        s.holding = 0        # the hold restarts with both wheels, where they are
    s.faultFlags = 0
    unmask_encoders(s)
    return None


def unmask_encoders(s: FirmwareState) -> None:
    """``unmaskEncoders``: the storm flags of the encoders whose storm a tick latched
    cleared (one masked since stays masked: the next tick latches its fault); the ISR
    model (``QuadratureDecoder``, driven by ``PortLoop``) sees them cleared and reads the
    pins afresh (``unmask``)."""
    if s.stormTickL:
        s.stormL = 0
    if s.stormTickR:
        s.stormR = 0


def dispatch(s: FirmwareState, body: bytes, out: bytearray) -> tuple[str | None, int, int]:
    """``dispatch``: (reason or None, data reply, parameter index). The firmware checks
    that the command is printable first; here each branch does (``parse`` for motion,
    cached), which gives the same answer: a keyword with a bad byte matches nothing.
    An unframed line after hello reaches only ``estop`` and the motion commands."""
    if s.unframedLine:
        if not all_printable(body):
            return "syntax", DATA_NONE, 0
        if body == b"estop":
            latch_estop(s, out)
            return None, DATA_NONE, 0
        if (body[:1] == b"x" or (body[:1] == b"r" and body[1:2] != b"e")
                or (len(body) >= 4 and body[:3] == b"ppm")):
            return move_to(s, body, out), DATA_NONE, 0
        return "unframed", DATA_NONE, 0
    if body == b"hello" or body == b"hello:4":
        s.tlmEnabled = 1
        s.linesFramed = 1 if body == b"hello:4" else 0   # protocol v4: the board's lines framed
        return None, DATA_HELLO, 0
    if body == b"estop":
        latch_estop(s, out)
        return None, DATA_NONE, 0
    if body == b"reset":
        return reset_estop(s), DATA_NONE, 0
    if body[:4] == b"get:":
        reason, i = parse_get(body)
        return reason, DATA_PARAM, i
    if body[:4] == b"set:":
        reason, i = parse_set(s, body)
        return reason, DATA_PARAM, i
    if body == b"save":
        return save_params(s), DATA_NONE, 0
    if body == b"defaults":
        restore_defaults(s)
        return None, DATA_NONE, 0
    return move_to(s, body, out), DATA_NONE, 0


def fields_expected(s: FirmwareState) -> int:
    """``fieldsExpected``: the fields the buffered command takes (2 for WHEEL and
    CMDVEL, 8 for PPM), or 0 when no command starts that way."""
    buf = s.cmdBuf
    if buf[:1] in (b"r", b"x"):
        return 2
    if len(buf) >= 4 and buf[:4] == b"ppm:":
        return C.PPM_CHANNELS
    return 0


def finish_command(s: FirmwareState, out: bytearray) -> None:
    """``finishCommand``: the buffered command, unframed when it starts with ``$``,
    dispatched and answered (to ``out``); then the buffer is emptied."""
    body = bytes(s.cmdBuf)
    seq, data, param = -1, DATA_NONE, 0
    reason: str | None = None
    s.unframedLine = 0
    if body[:1] == b"$":
        reason, seq, body = unframe(body)
        if seq >= 0:
            s.lastSeq = seq
        if reason == "checksum":
            s.crcRejected = (s.crcRejected + 1) & 0xFFFFFFFF
    elif s.tlmEnabled:
        s.unframedLine = 1                  # after hello: only what makes the chair safer
    if reason is None:
        reason, data, param = dispatch(s, body, out)
    if reason is not None:
        s.rejectedCount = (s.rejectedCount + 1) & 0xFFFFFFFF
    if reason is not None or seq >= 0 or data != DATA_NONE:
        answer(s, reason, seq, data, param, out)
    _reset(s)


def _reset(s: FirmwareState) -> None:
    s.cmdBuf = bytearray()
    s.cmdLen = 0
    s.cmdCommas = 0


def rx_gap(s: FirmwareState, lost: int) -> None:
    """``rxGap(lost)``: bytes were lost before the next one (``lost``: bytes dropped for
    a full RX ring, plus one for a USART overrun). The command being received is thrown
    away, and so is what follows up to the next ``,`` or line end, which is answered
    ``ERR:overrun``: the lost bytes may have held a line end, and the two pieces must not
    join into one command."""
    s.rxGaps = (s.rxGaps + lost) & 0xFFFFFFFF
    _reset(s)
    s.cmdDiscarding = DISCARD_OVERRUN


def process_byte(s: FirmwareState, c: int, out: bytearray) -> None:
    """One received byte, as ``processByte`` handles it."""
    s.rxCount = (s.rxCount + 1) & 0xFFFFFFFF
    if c == NEWLINE or c == RETURN:
        if s.cmdDiscarding == DISCARD_OVERRUN:
            s.cmdDiscarding = DISCARD_NONE
            reject(s, "overrun", out)
        elif s.cmdDiscarding:
            s.cmdDiscarding = DISCARD_NONE
        elif s.cmdLen > 0:
            finish_command(s, out)
        return
    if s.cmdDiscarding:
        if c == COMMA and s.cmdDiscarding == DISCARD_OVERRUN:
            s.cmdDiscarding = DISCARD_NONE
            reject(s, "overrun", out)
        elif c == COMMA and s.cmdDiscarding == DISCARD_TO_COMMA:
            s.cmdDiscarding = DISCARD_NONE
        return
    if s.cmdLen >= C.CMD_MAX_LEN:
        reject(s, "overlong", out)
        if s.cmdBuf[0] == DOLLAR:
            s.cmdDiscarding = DISCARD_TO_EOL
        else:
            s.cmdDiscarding = DISCARD_NONE if c == COMMA else DISCARD_TO_COMMA
        _reset(s)
        return
    s.cmdBuf.append(c)
    s.cmdLen += 1
    if c != COMMA or s.cmdBuf[0] == DOLLAR:
        return
    s.cmdCommas += 1
    expected = fields_expected(s)
    if expected == 0:
        reject(s, "unframed" if s.tlmEnabled else "syntax", out)
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
                s.rxCount = (s.rxCount + j - i) & 0xFFFFFFFF
                i = j
                continue
        process_byte(s, data[i], out)
        i += 1
