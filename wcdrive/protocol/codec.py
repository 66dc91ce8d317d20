"""The serial protocol's codec: pure functions and an incremental line decoder, no I/O.

Host to board:  ``encode_cmdvel(v, w)`` -> ``b"x:0.500,t:0.100,"`` (the seed host's
format), ``encode_wheel(right, left)`` -> ``b"rp5.000,lp3.000,"``, ``encode_ppm``.
Protocol v3:    ``frame(command, seq)`` -> ``b"$17:x:0.500,t:0.100,*DBDA\\n"`` (CRC-16),
``encode_get(name)``, ``encode_set(name, value)``, ``HELLO``, ``ESTOP``, ``RESET``.
Board to host:  ``LineDecoder.feed(data)`` returns the complete lines' messages:
``Feedback``, ``ExtendedTelemetry``, ``Error``, ``Event``, ``Boot``, ``Hello``,
``Param``, ``Ack``, ``Nak`` or ``Unknown``.
"""

from __future__ import annotations

import binascii
import math
import re
from dataclasses import dataclass

from wcdrive.protocol.spec import PARAMETERS, integer, real

MAX_LINEAR = real("MAX_LINEAR")
MAX_ANGULAR = real("MAX_ANGULAR")
MAX_WHEEL = real("MAX_WHEEL_SPEED")
MAX_LINE = 256
SEQ_MAX = integer("SEQ_MAX")
PROTOCOL_VERSION_PLAIN = integer("PROTOCOL_VERSION_PLAIN")


def _finite(name: str, value: float, limit: float) -> float:
    value = float(value)
    if math.isnan(value) or math.isinf(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if abs(value) > limit:
        raise ValueError(f"{name}={value} is outside ±{limit}")
    return value


def crc16(data: bytes) -> int:
    """CRC-16/XMODEM (poly 0x1021, init 0, no reflection, no final XOR) of ``data``: the
    ``*CCCC`` of a v3 frame covers the bytes between ``$`` and ``*``. It is Python's
    ``binascii.crc_hqx(data, 0)`` and avr-libc's ``_crc_xmodem_update`` on the board."""
    return binascii.crc_hqx(data, 0)


def frame(command: bytes, seq: int) -> bytes:
    """A protocol v3 frame: ``$<seq>:<command>*<CCCC>\\n`` (``seq`` 0..65535, CCCC the
    CRC-16/XMODEM in upper-case hex). The command may keep its trailing comma; the board
    acts on it at the line end only."""
    if not 0 <= seq <= SEQ_MAX:
        raise ValueError(f"sequence number {seq} is outside 0..{SEQ_MAX}")
    inner = b"%d:" % seq + command
    return b"$" + inner + b"*%04X\n" % crc16(inner)


#: The line counter of a protocol v4 board line wraps at this.
LINE_COUNTER_WRAP = integer("LINE_COUNTER_WRAP")


def board_frame(text: bytes, counter: int) -> bytes:
    """A protocol v4 board line: ``<text>#<NN>*<CCCC>\r\n``, NN the line counter
    (0..255, two upper-case hex digits, one more for each line the board sends, wrapping)
    and CCCC the CRC-16/XMODEM of everything before the ``*``, as a v3 frame's. The text
    stays first, so that the line reads as before in a terminal; 8 bytes more a line."""
    if not 0 <= counter < LINE_COUNTER_WRAP:
        raise ValueError(f"line counter {counter} is outside 0..{LINE_COUNTER_WRAP - 1}")
    inner = text + b"#%02X" % counter
    return inner + b"*%04X\r\n" % crc16(inner)


_BOARD_FRAME = re.compile(rb"(.*)#([0-9A-F]{2})\*([0-9A-F]{4})", re.DOTALL)
#: How a line that claims to be a v4 frame ends (no line of v3 has ``*`` or ``#``).
_FRAME_END = re.compile(rb"[#*][^#*]{0,6}\Z")


def _split_frame(line: bytes) -> tuple[bytes, int, bool] | None:
    """``(text, counter, CRC good)`` of a line without its ``\r\n`` that has the shape
    of a v4 board line, else None."""
    m = _BOARD_FRAME.fullmatch(line) if _FRAME_END.search(line) else None
    if m is None:
        return None
    return m[1], int(m[2], 16), crc16(line[:m.start(3) - 1]) == int(m[3], 16)


def board_unframe(line: bytes) -> tuple[bytes, int] | None:
    """``(text, counter)`` of a v4 board line without its ``\r\n``, or None when it is
    not one or its CRC is wrong: a line the host must not believe."""
    split = _split_frame(line)
    if split is None or not split[2]:
        return None
    return split[0], split[1]


HELLO = b"hello\n"
ESTOP = b"estop\n"
RESET = b"reset\n"
#: Parameters in EEPROM: store those in force; the defaults back (PROTOCOL.md).
SAVE = b"save\n"
DEFAULTS = b"defaults\n"
#: The runtime parameters and their ranges (protocol/PROTOCOL.md, "Parameters").
PARAM_RANGES: dict[str, tuple[float, float]] = {p.name: (p.low, p.high) for p in PARAMETERS}
#: The parameters that take whole numbers (1 to 4 digits on the wire).
INTEGER_PARAMS = frozenset(p.name for p in PARAMETERS if p.integer)


def _param_name(name: str) -> str:
    if name not in PARAM_RANGES:
        raise ValueError(f"unknown parameter {name!r}; one of {', '.join(PARAM_RANGES)}")
    return name


def encode_get(name: str) -> bytes:
    """``get:<name>`` (ValueError for an unknown parameter)."""
    return f"get:{_param_name(name)}".encode()


def encode_set(name: str, value: float) -> bytes:
    """``set:<name>=<value>``; checked against the range the firmware enforces."""
    low, high = PARAM_RANGES[_param_name(name)]
    value = float(value)
    if not (low <= value <= high):
        raise ValueError(f"{name}={value} is outside {low} .. {high}")
    if name in INTEGER_PARAMS:
        if value != int(value):
            unit = " of milliseconds" if name == "watchdog_ms" else ""
            raise ValueError(f"{name} is a whole number{unit}")
        return f"set:{name}={int(value)}".encode()
    if abs(value) < 1e-99:
        # 0 in binary32 as on the board, and "1e-100" has more exponent digits than
        # the board takes (NUMBER_MAX_EXP_DIGITS: ERR:range).
        value = 0.0
    return f"set:{name}={value:.6g}".encode()


def encode_cmdvel(linear: float, angular: float) -> bytes:
    """``x:<m/s>,t:<rad/s>,`` with 3 decimals, as the seed's ``wc_control`` node sends it."""
    v = _finite("linear", linear, MAX_LINEAR)
    w = _finite("angular", angular, MAX_ANGULAR)
    return f"x:{v:.3f},t:{w:.3f},".encode()


def encode_wheel(right: float, left: float) -> bytes:
    """``r<p|n><rad/s>,l<p|n><rad/s>,``: the sign as ``p``/``n``."""
    r = _finite("right", right, MAX_WHEEL)
    l_ = _finite("left", left, MAX_WHEEL)
    return (f"r{'n' if r < 0 else 'p'}{abs(r):.3f},l{'n' if l_ < 0 else 'p'}{abs(l_):.3f},").encode()


def encode_ppm(channels: list[int] | tuple[int, ...]) -> bytes:
    """``ppm:c1,...,c8,``: eight pulse widths in µs, integers 0..9999."""
    if len(channels) != 8:
        raise ValueError("a PPM frame has 8 channels")
    for c in channels:
        if not isinstance(c, int) or not 0 <= c <= 9999:
            raise ValueError(f"PPM channel {c!r} is not an integer 0..9999 (microseconds)")
    return ("ppm:" + ",".join(str(c) for c in channels) + ",").encode()


@dataclass(frozen=True, slots=True)
class Feedback:
    """``ENC:l,r,VEL:l,r,MODE:m``: raw counts (left mirrored) and rad/s (2 decimals);
    also the line with ``feedback_form`` 1's ``,r<p|n><v>,l<p|n><v>`` after ``MODE``."""

    count_left: int
    count_right: int
    vel_left: float
    vel_right: float
    mode: str


@dataclass(frozen=True, slots=True)
class Error:
    """``ERR:<reason>``: a command the board rejected (protocol/PROTOCOL.md). A message
    the board sent, not an exception: the host logs it and keeps ``reason`` in
    ``chair.errors``; what wcdrive raises derives from ``wcdrive.errors.WcdriveError``."""

    reason: str


@dataclass(frozen=True, slots=True)
class Event:
    """``EVT:<name>``: ``WATCHDOG``, ``PPM_LOST``, ``ESTOP``; ``NOT_NEUTRAL`` (motion
    refused until a neutral command), ``NEUTRAL`` (neutral confirmed after that),
    ``DEFLECTED`` (refused 5 s without one); on a grade ``ROLLAWAY``,
    ``OVERSPEED``, ``STALLED_ON_GRADE`` (the chair's limits, not faults); ``FAULT,<fault>`` (a latched
    fault: ``ENC_STALL_L``, ``ENC_REVERSED_R``, ``DRIVER_DEAD``, ...; PROTOCOL.md), or at
    boot ``PARAMS_LOADED`` / ``PARAMS_DEFAULT,<why>`` (the parameters saved in EEPROM)."""

    name: str

    @property
    def fault(self) -> str | None:
        """The fault's name for ``EVT:FAULT,<fault>``, else None."""
        return self.name[6:] if self.name.startswith("FAULT,") else None

    @property
    def params_default(self) -> str | None:
        """Why the board booted with the default parameters, for
        ``EVT:PARAMS_DEFAULT,<why>`` (``blank``, ``version``, ``crc``, ``range``: its
        EEPROM held no good saved block), else None."""
        return self.name[15:] if self.name.startswith("PARAMS_DEFAULT,") else None


@dataclass(frozen=True, slots=True)
class Boot:
    """``BOOT:<text>``: the board has reset; ``text`` is the firmware's name and, since
    firmware 3.1, the reset cause after a comma (``final_control,WATCHDOG``)."""

    text: str

    @property
    def cause(self) -> str:
        """The reset cause (``POWER_ON``, ``EXTERNAL``, ``BROWN_OUT``, ``WATCHDOG``,
        ``JTAG``, ``NONE``), or "" when the line names none."""
        return self.text.partition(",")[2]


@dataclass(frozen=True, slots=True)
class Unknown:
    """A line that matches none of the board's formats (or an overlong one), as received."""

    line: bytes


@dataclass(frozen=True, slots=True)
class Corrupt:
    """A board line the host must not believe: a v4 frame whose CRC is wrong, or, once
    the board frames its lines, one that is not a frame. ``spliced``: its frame ends
    well but its counter is not the one expected next, as when the head of one line
    met the tail of a later one (bytes lost between them)."""

    line: bytes
    spliced: bool = False


#: The fault bits of ``TLM``'s last field and of ``EVT:FAULT,<name>``, bit 0 first
#: (protocol/PROTOCOL.md, "Faults").
FAULT_NAMES = ("ENC_STALL_L", "ENC_STALL_R", "ENC_REVERSED_L", "ENC_REVERSED_R",
               "ENC_IMPLAUSIBLE_L", "ENC_IMPLAUSIBLE_R", "DRIVER_DEAD", "MOTOR_L", "MOTOR_R",
               "BRAKE_OPEN", "BRAKE_SHORT", "OVERHEAT_L", "OVERHEAT_R", "UNDERVOLT", "CURRENT_SENSE")


def fault_names(faults: int) -> tuple[str, ...]:
    """The names of the fault bits set in ``faults``."""
    return tuple(name for i, name in enumerate(FAULT_NAMES) if faults & (1 << i))


@dataclass(frozen=True, slots=True)
class ExtendedTelemetry:
    """``TLM:`` (v2): the tick's inputs and outputs beyond the feedback line."""

    millis: int
    rx: int
    seq: int
    pwm_left: int
    pwm_right: int
    dir_left: int
    dir_right: int
    illegal_left: int
    illegal_right: int
    flags: int
    rejected: int
    crc_rejected: int
    free_ram: int
    faults: int = 0
    #: Bytes the board lost on receive (a full RX ring, one per USART overrun), counted
    #: since boot; each loss also discards the command it hit (``ERR:overrun``).
    rx_lost: int = 0
    #: Control ticks that ran more than a period late since boot (the 50 ms grid then
    #: starts again from that tick).
    late: int = 0
    #: Bit 0: the board waits for a neutral command (motion refused, ``ERR:neutral``);
    #: bit 1: the neutral fault (refused 5 s without one); bit 2: driving inhibited by
    #: an inhibit input (``ERR:inhibit``); bit 3: the speed capped by one; bit 4: a fitted
    #: parking brake applied (``brake_fitted`` 1, its pin LOW); bit 5: push mode (the
    #: brake released by hand); bit 6: the thermal rollback; bit 7: the low-battery
    #: rollback; bits 8-9: the drive profile in force. Boards before this field end at
    #: ``late`` (None).
    state: int | None = None
    #: The supply the board measures, filtered, in tenths of a volt (``supply_v``).
    #: Boards before this field end at ``state`` (None).
    supply_dv: int | None = None

    @property
    def needs_neutral(self) -> bool:
        """State bit 0: motion is refused until a neutral (zero) command stands."""
        return bool(self.state and self.state & 1)

    @property
    def neutral_fault(self) -> bool:
        """State bit 1: motion was refused for 5 s without a neutral command (a control
        deflected at switch-on, or stuck)."""
        return bool(self.state and self.state & 2)

    @property
    def drive_inhibited(self) -> bool:
        """State bit 2: an inhibit input that stops the chair is engaged (the charger):
        motion is refused (``ERR:inhibit``)."""
        return bool(self.state and self.state & 4)

    @property
    def speed_capped(self) -> bool:
        """State bit 3: an inhibit input that caps the speed is engaged (the seat raised)."""
        return bool(self.state and self.state & 8)

    @property
    def brake_applied(self) -> bool:
        """State bit 4: the parking brake the firmware owns (``brake_fitted`` 1) is
        applied, its pin LOW: the chair parked on it, or stopping after a fault."""
        return bool(self.state and self.state & 16)

    @property
    def push_mode(self) -> bool:
        """State bit 5: the brake's manual-release lever is pulled (push mode): motion is
        refused (``ERR:inhibit``, bit 2 set too) and the motors freewheel."""
        return bool(self.state and self.state & 32)

    @property
    def thermal_rollback(self) -> bool:
        """State bit 6: a motor's estimated winding temperature is past the rollback's
        start: its current limit and the top speed are lowered (``EVT:THERMAL,1``)."""
        return bool(self.state and self.state & 64)

    @property
    def battery_low(self) -> bool:
        """State bit 7: the filtered supply is below BATTERY_LOW_V: the top speed is
        lowered (``EVT:BATTERY,1``)."""
        return bool(self.state and self.state & 128)

    @property
    def drive_profile(self) -> int | None:
        """State bits 8-9: the drive profile in force (``set:profile``); None from a
        board that does not send the state."""
        return None if self.state is None else (self.state >> 8) & 3

    @property
    def supply_v(self) -> float | None:
        """The battery voltage the board measures (filtered, V); None from a board that
        does not send it."""
        return None if self.supply_dv is None else self.supply_dv / 10.0

    @property
    def fault_latched(self) -> bool:
        """Flag bit 7: a fault is latched (``faults`` says which; motion is refused)."""
        return bool(self.flags & 128)

    @property
    def fault_names(self) -> tuple[str, ...]:
        """The latched faults by name (``FAULT_NAMES``)."""
        return fault_names(self.faults)

    @property
    def watchdog_armed(self) -> bool:
        """Flag bit 0: the watchdog is armed."""
        return bool(self.flags & 1)

    @property
    def emergency_ramp(self) -> bool:
        """Flag bit 1: the setpoints ramp at the emergency rate (watchdog, PPM loss, e-stop)."""
        return bool(self.flags & 2)

    @property
    def estop_latched(self) -> bool:
        """Flag bit 2: the e-stop is latched."""
        return bool(self.flags & 4)

    @property
    def ppm_lost(self) -> bool:
        """Flag bit 3: a PPM frame said the receiver lost the transmitter."""
        return bool(self.flags & 8)

    @property
    def parked(self) -> bool:
        """Flag bit 4: parked (at rest, integrators reset, both PWM outputs 0)."""
        return bool(self.flags & 16)

    @property
    def pivot_phase(self) -> int:
        """Flag bits 5-6: the pivot phase (0 none, 1 stopping, 2 rotating)."""
        return (self.flags >> 5) & 3


@dataclass(frozen=True, slots=True)
class Hello:
    """``HELLO:<version>,<firmware>[,<firmware version>,<build id>[,<profile>]]``: the
    answer to ``hello`` (v2 boards name the firmware only; v3 add its version and build
    id; boards with drive profiles the profile in force, ``None`` from a board before)."""

    version: int
    firmware: str
    firmware_version: str = ""
    build_id: str = ""
    profile: int | None = None

    @property
    def lines_framed(self) -> bool:
        """The board frames its lines from this one on (protocol v4 and later)."""
        return self.version > PROTOCOL_VERSION_PLAIN


@dataclass(frozen=True, slots=True)
class Param:
    """``PAR:<name>,<value>``: the value in force, the answer to ``get:`` and ``set:``."""

    name: str
    value: float


@dataclass(frozen=True, slots=True)
class Ack:
    """``ACK:<seq>``: the framed line with this sequence number was carried out."""

    seq: int


@dataclass(frozen=True, slots=True)
class Nak:
    """``NAK:<seq>,<reason>``: the framed line with this sequence number was refused."""

    seq: int
    reason: str


Message = (Feedback | ExtendedTelemetry | Error | Event | Boot | Hello | Param | Ack | Nak
           | Unknown | Corrupt)

_NUMBER = rb"-?(?:\d+(?:\.\d*)?|nan|inf|ovf)"
_FEEDBACK = re.compile(
    rb"ENC:(-?\d+),(-?\d+),VEL:(" + _NUMBER + rb"),(" + _NUMBER + rb"),MODE:(WHEEL|CMDVEL|PPM)"
    # feedback_form 1: the wheels' speeds again, for ros2_control plugins (the VEL fields
    # carry the same numbers, so the tail is matched and left)
    rb"(?:,r[pn](?:\d+\.\d+|nan|inf|ovf),l[pn](?:\d+\.\d+|nan|inf|ovf))?")


_MODES = {b"WHEEL": "WHEEL", b"CMDVEL": "CMDVEL", b"PPM": "PPM"}


def _float(text: bytes) -> float:
    """A number as ``_NUMBER`` matched it: ``float`` reads the rest, signs included."""
    if text.endswith(b"ovf"):
        return -math.inf if text.startswith(b"-") else math.inf
    return float(text)


_TLM = re.compile(rb"TLM:(\d+(?:,\d+){12}(?:,\d+){0,5})")
_HELLO = re.compile(rb"HELLO:(\d+),([\w.-]+)(?:,([\w.-]+),([0-9a-f]+)(?:,(\d))?)?")
_PARAM = re.compile(rb"PAR:(\w+),(\d+(?:\.\d+)?)")
_ACK = re.compile(rb"ACK:(\d+)")
_NAK = re.compile(rb"NAK:(\d+),(\w+)")


def parse_line(line: bytes) -> Message:
    """One line without its ``\\r\\n``: a v4 frame's text when its CRC holds
    (``Corrupt`` when not), else the line as it is."""
    if _FRAME_END.search(line):
        unframed = board_unframe(line)
        if unframed is None:
            return Corrupt(line)
        line = unframed[0]
    return _parse_text(line)


def _parse_text(line: bytes) -> Message:
    m = _FEEDBACK.fullmatch(line)
    if m:
        left, right, vel_left, vel_right, mode = m.groups()
        return Feedback(int(left), int(right), _float(vel_left), _float(vel_right), _MODES[mode])
    m = _TLM.fullmatch(line)
    if m:
        return ExtendedTelemetry(*(int(v) for v in m[1].split(b",")))
    m = _ACK.fullmatch(line)
    if m:
        return Ack(int(m[1]))
    m = _NAK.fullmatch(line)
    if m:
        return Nak(int(m[1]), m[2].decode())
    m = _PARAM.fullmatch(line)
    if m:
        return Param(m[1].decode(), float(m[2]))
    m = _HELLO.fullmatch(line)
    if m:
        return Hello(int(m[1]), m[2].decode(), (m[3] or b"").decode(), (m[4] or b"").decode(),
                     None if m[5] is None else int(m[5]))
    if line.startswith(b"ERR:"):
        return Error(line[4:].decode("ascii", "replace"))
    if line.startswith(b"EVT:"):
        return Event(line[4:].decode("ascii", "replace"))
    if line.startswith(b"BOOT:"):
        return Boot(line[5:].decode("ascii", "replace"))
    return Unknown(line)


@dataclass(slots=True)
class LineStats:
    """What a ``LineDecoder`` made of the board's lines: ``good`` (believed: unframed
    before v4, v4 frames with a good CRC), ``bad_crc`` (``Corrupt``, not spliced),
    ``spliced`` (``Corrupt`` with a counter out of turn) and ``lost`` (framed lines the
    counter says were sent but never came, less the bad and spliced lines met in the
    gap). With framed lines only, ``good + bad_crc + spliced + lost`` is the number of
    lines the board sent, as long as no run of 256 lines or more went missing at once
    and no line was cut in two."""

    good: int = 0
    bad_crc: int = 0
    spliced: int = 0
    lost: int = 0

    @property
    def total(self) -> int:
        """``good + bad_crc + spliced + lost``."""
        return self.good + self.bad_crc + self.spliced + self.lost


class LineDecoder:
    """Incremental: feed bytes as they come, get the messages of complete lines.
    A line longer than ``MAX_LINE`` bytes is dropped (as ``Unknown``) to bound memory.
    A board that resets while it sends a line starts its ``BOOT:`` line where the cut
    line stopped: the cut part is an ``Unknown``, the ``BOOT:`` line a ``Boot``.

    Protocol v4: a framed line is unframed, or is a ``Corrupt`` when its CRC is wrong,
    and its counter is followed (``stats``). Once ``framed`` is set (the board answered
    ``hello:4``) every line must be a frame and any other is a ``Corrupt``, but for a
    ``BOOT:`` line: the board has reset and frames nothing until the next hello, so
    ``framed`` is cleared."""

    def __init__(self, stats: LineStats | None = None) -> None:
        self._buf = bytearray()
        self.stats = stats if stats is not None else LineStats()
        self.framed = False
        self._expected: int | None = None     # the counter of the next framed line
        self._bad_since_good = 0              # bad lines since the last good framed one

    def resync(self) -> None:
        """Forgets the line counter: the next framed line starts the count (the board
        has reset, or the link was reopened)."""
        self._expected = None
        self._bad_since_good = 0

    def feed(self, data: bytes) -> list[Message]:
        """Appends ``data``; returns the messages of the lines it completed (each ends
        at ``\\n``; trailing ``\\r`` are dropped)."""
        if (not self._buf and type(data) is bytes and data and data.find(b"\n") == len(data) - 1
                and data.find(b"BOOT:", 1) < 0):
            # one whole line, nothing held: what the loop below makes of it, without the copies
            return [self._line(data[:-1].rstrip(b"\r"))]
        self._buf += data
        out: list[Message] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > MAX_LINE:
                    out.append(self._bad(Unknown(bytes(self._buf))))
                    self._buf.clear()
                return out
            line = bytes(self._buf[:i]).rstrip(b"\r")
            del self._buf[:i + 1]
            boot = line.find(b"BOOT:", 1)
            if boot > 0:
                out.append(self._bad(Unknown(line[:boot])))
                line = line[boot:]
            out.append(self._line(line))

    def _line(self, line: bytes) -> Message:
        """One whole line: unframed, checked and counted."""
        stats = self.stats
        split = _split_frame(line)
        if split is None:
            msg = _parse_text(line)
            if isinstance(msg, Boot):
                self.framed = False
                self.resync()
            elif self.framed:
                return self._bad(Corrupt(line))
            stats.good += 1
            return msg
        text, counter, crc_good = split
        if not crc_good:
            spliced = self._expected is not None and counter != self._expected
            self._bad_since_good += 1
            if spliced:
                stats.spliced += 1
            else:
                stats.bad_crc += 1
            return Corrupt(line, spliced)
        if self._expected is not None:
            gap = (counter - self._expected) % LINE_COUNTER_WRAP
            stats.lost += max(0, gap - self._bad_since_good)
        self._expected = (counter + 1) % LINE_COUNTER_WRAP
        self._bad_since_good = 0
        stats.good += 1
        return _parse_text(text)

    def _bad(self, msg: Unknown | Corrupt) -> Message:
        """A line that is no frame (cut short, overlong): a ``Corrupt`` once lines are
        framed."""
        if not self.framed:
            return msg
        self._bad_since_good += 1
        self.stats.bad_crc += 1
        return Corrupt(msg.line)
