"""The serial protocol's messages as CAN frames (protocol/CAN.md, protocol/wcdrive.dbc).

Pure functions, no bus. Host to chair: ``command_to_frames(line)`` turns one protocol
line the host would send (seed form or a framed v2 line) into frames, and
``frame_to_command(id, data)`` turns a frame back into a protocol line for the
board. Chair to host: ``message_to_frames(message)`` (a decoded board line) and
``TelemetryAssembler``/``frame_to_lines`` turn frames back into the board's lines.

Values keep the serial protocol's resolution: speeds in mm/s and mrad/s (the seed
host's 3 decimals), measured wheel speeds in 0.01 rad/s (the firmware prints 2), and
a parameter value is carried as the binary32 the board's ``strtod`` made of the host's
text, then written back as a decimal string the board's ``strtod`` turns into the
same binary32.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.f32 import bits
from wcdrive.errors import WcdriveError
from wcdrive.protocol.codec import (
    INTEGER_PARAMS,
    Ack,
    Boot,
    Error,
    Event,
    ExtendedTelemetry,
    Feedback,
    Hello,
    Message,
    Nak,
    Param,
    crc16,
    frame,
)
from wcdrive.protocol.motion import VelocityCommand, WheelCommand, parse_motion
from wcdrive.protocol.spec import PARAMETERS

# Host -> chair
CMD_VEL = 0x300
CMD_WHEELS = 0x301
CONTROL = 0x302
PARAM = 0x303
# Chair -> host
FEEDBACK_ENC = 0x310
FEEDBACK_VEL = 0x311
STATUS_A = 0x312
STATUS_B = 0x313
STATUS_C = 0x314
STATUS_D = 0x315
REPLY = 0x316
STATUS_E = 0x317
STATUS_F = 0x318
HELLO_E = 0x319

HOST_TO_CHAIR = (CMD_VEL, CMD_WHEELS, CONTROL, PARAM)
CHAIR_TO_HOST = (FEEDBACK_ENC, FEEDBACK_VEL, STATUS_A, STATUS_B, STATUS_C, STATUS_D, REPLY, STATUS_E,
                 STATUS_F, HELLO_E)

CONTROL_OPS = {1: b"hello", 2: b"estop", 3: b"reset", 4: b"save", 5: b"defaults", 6: b"hello:4"}
#: WC_PARAM's indices: each parameter's ``can_index`` in the spec, else the parameters
#: without one in the table's order (an index once given keeps its parameter).
_UNINDEXED = iter(range(len(PARAMETERS)))
_CAN_INDEX = {p.name: p.can_index if p.can_index is not None else next(_UNINDEXED) for p in PARAMETERS}
PARAM_NAMES = tuple(sorted(_CAN_INDEX, key=_CAN_INDEX.__getitem__))
MODES = ("WHEEL", "CMDVEL", "PPM")
REASONS = ("", "syntax", "number", "range", "fields", "overlong", "checksum", "estop", "busy",
           "param", "unframed", "fault", "overrun", "limit", "neutral",
           "inhibit")
EVENTS = ("", "WATCHDOG", "PPM_LOST", "ESTOP", "FAULT,ENC_STALL_L", "FAULT,ENC_STALL_R",
          "FAULT,ENC_REVERSED_L", "FAULT,ENC_REVERSED_R", "FAULT,ENC_IMPLAUSIBLE_L",
          "FAULT,ENC_IMPLAUSIBLE_R", "FAULT,DRIVER_DEAD", "FAULT,MOTOR_L", "FAULT,MOTOR_R",
          "PARAMS_LOADED", "PARAMS_DEFAULT,blank", "PARAMS_DEFAULT,version", "PARAMS_DEFAULT,crc",
          "PARAMS_DEFAULT,range", "ROLLAWAY", "OVERSPEED", "STALLED_ON_GRADE", "NOT_NEUTRAL", "NEUTRAL",
          "DEFLECTED", "INHIBIT,1,1", "INHIBIT,1,0", "INHIBIT,2,1", "INHIBIT,2,0", "FAULT,BRAKE_OPEN",
          "FAULT,BRAKE_SHORT", "PUSH,1", "PUSH,0", "FAULT,OVERHEAT_L", "FAULT,OVERHEAT_R", "THERMAL,1",
          "THERMAL,0", "FAULT,UNDERVOLT", "BATTERY,1", "BATTERY,0", "FAULT,CURRENT_SENSE", "STALL_TIMEOUT")
#: BOOT reply codes: the reset cause (0: the line named none).
BOOT_CAUSES = ("", "POWER_ON", "EXTERNAL", "BROWN_OUT", "WATCHDOG", "JTAG", "NONE")
KIND_ACK, KIND_NAK, KIND_ERR, KIND_EVT, KIND_PAR, KIND_HELLO, KIND_BOOT = range(1, 8)
FIRMWARE = "final_control"

_FRAMED = re.compile(rb"\$(\d{1,5}):(.*)\*([0-9A-F]{4})")


class CanCodecError(WcdriveError, ValueError):
    """A line or frame that has no counterpart on the other side."""


def _seq_bytes(seq: int | None) -> tuple[int, int]:
    return (0, 0) if seq is None else (1, seq)


def _milli(number: float) -> int:
    value = round(number * 1000)
    if not -32768 <= value <= 32767:
        raise CanCodecError(f"{number!r} does not fit the frame's int16 (x 0.001)")
    return value


def command_to_frames(line: bytes) -> list[tuple[int, bytes]]:
    """One host line (``x:0.500,t:0.100,``, ``$17:estop*hh\\n``, ...) as CAN frames."""
    body = line.strip(b"\r\n")
    seq = None
    m = _FRAMED.fullmatch(body)
    if m:
        inner = body[1:-5]
        if crc16(inner) != int(m[3], 16):
            raise CanCodecError(f"bad CRC in {line!r}")
        seq = int(m[1])
        body = m[2]
    has_seq, seq_value = _seq_bytes(seq)
    tail = struct.pack("<BBH", 0, has_seq, seq_value)
    command = parse_motion(body)
    if isinstance(command, VelocityCommand):
        return [(CMD_VEL, struct.pack("<hh", _milli(command.linear), _milli(command.angular)) + tail)]
    if isinstance(command, WheelCommand):
        return [(CMD_WHEELS, struct.pack("<hh", _milli(command.right), _milli(command.left)) + tail)]
    for op, word in CONTROL_OPS.items():
        if body == word:
            return [(CONTROL, struct.pack("<BBBBHH", op, 0, 0, has_seq, 0, seq_value))]
    if body.startswith((b"get:", b"set:")):
        op = 1 if body.startswith(b"get:") else 2
        name, _, text = body[4:].partition(b"=")
        if name.decode() not in PARAM_NAMES:
            raise CanCodecError(f"unknown parameter in {line!r}")
        value = strtod(text)[0] if op == 2 else 0.0
        return [(PARAM, struct.pack("<BBHf", op | has_seq << 7, PARAM_NAMES.index(name.decode()),
                                    seq_value, value))]
    raise CanCodecError(f"no CAN frame for {line!r} (PPM comes from the RC receiver, not CAN)")


def board_text(value: float) -> bytes:
    """The shortest decimal text that avr-libc's strtod (the board's) turns into exactly
    the binary32 ``value``."""
    # avr-libc's strtod is not correctly rounded and its result depends on the digits
    # written (trailing zeros included), so the nearest decimal can land an ulp off:
    # search decimals of each length around the value, shortest first.
    if value < 0 or value != value:
        raise CanCodecError(f"no decimal text for {value!r}")
    for decimals in range(13):
        scale = 10**decimals
        base = round(value * scale)
        for delta in sorted(range(-12, 13), key=abs):   # avr-libc can be 2 ulp off
            m = base + delta
            if m < 0:
                continue
            digits = str(m).rjust(decimals + 1, "0")
            text = digits[:len(digits) - decimals] + ("." + digits[-decimals:] if decimals else "")
            for zeros in range(4):
                candidate = (text if zeros == 0 else
                             (text if "." in text else text + ".") + "0" * zeros).encode()
                if bits(strtod(candidate)[0]) == bits(value):
                    return candidate
    # Too small for 12 decimals (down to the subnormals): a mantissa and an exponent.
    for significant in range(6, 13):
        mantissa, _, exponent = f"{value:.{significant - 1}e}".partition("e")
        whole = int(mantissa.replace(".", ""))
        for delta in sorted(range(-12, 13), key=abs):
            m = whole + delta
            if m <= 0:
                continue
            text = str(m)
            if len(text) != significant:                 # carried into another decade
                continue
            candidate = f"{text[0]}.{text[1:]}e{int(exponent)}".encode()
            if bits(strtod(candidate)[0]) == bits(value):
                return candidate
    raise CanCodecError(f"no decimal text for {value!r}")


def frame_to_command(can_id: int, data: bytes) -> bytes:
    """A host-to-chair frame as the protocol line for the board: a v3 frame with the
    host's sequence number, or 0 when the frame carries none."""
    seq: int | None
    if can_id in (CMD_VEL, CMD_WHEELS):
        a, b, _, has_seq, seq_value = struct.unpack("<hhBBH", data[:8])
        if can_id == CMD_VEL:
            body = f"x:{a / 1000:.3f},t:{b / 1000:.3f},".encode()
        else:
            body = (f"r{'n' if a < 0 else 'p'}{abs(a) / 1000:.3f},"
                    f"l{'n' if b < 0 else 'p'}{abs(b) / 1000:.3f},").encode()
        seq = seq_value if has_seq else None
    elif can_id == CONTROL:
        op, _, _, has_seq, _, seq_value = struct.unpack("<BBBBHH", data[:8])
        if op not in CONTROL_OPS:
            raise CanCodecError(f"unknown control op {op}")
        body = CONTROL_OPS[op]
        seq = seq_value if has_seq else None
    elif can_id == PARAM:
        op_flags, index, seq_value, value = struct.unpack("<BBHf", data[:8])
        if index >= len(PARAM_NAMES) or op_flags & 0x7F not in (1, 2):
            raise CanCodecError(f"bad parameter frame {data.hex()}")
        name = PARAM_NAMES[index].encode()
        if op_flags & 0x7F == 1:
            body = b"get:" + name
        elif name.decode() in INTEGER_PARAMS:
            body = b"set:" + name + b"=%d" % round(value)
        else:
            body = b"set:" + name + b"=" + board_text(value)
        seq = seq_value if op_flags & 0x80 else None
    else:
        raise CanCodecError(f"frame 0x{can_id:03X} is not a command")
    return frame(body, 0 if seq is None else seq)


def _clamp16(x: float) -> int:
    value = round(x * 100) if x == x else 0
    return max(-32768, min(32767, value))


def _sat16(count: int) -> int:
    return min(count, 0xFFFF)


def message_to_frames(msg: Message) -> list[tuple[int, bytes]]:
    """A decoded board line as chair-to-host frames (unknown lines have none)."""
    if isinstance(msg, Feedback):
        return [(FEEDBACK_ENC, struct.pack("<ii", msg.count_left, msg.count_right)),
                (FEEDBACK_VEL, struct.pack("<hhB", _clamp16(msg.vel_left), _clamp16(msg.vel_right),
                                           MODES.index(msg.mode)))]
    if isinstance(msg, ExtendedTelemetry):
        t = msg
        return [(STATUS_A, struct.pack("<II", t.millis, t.rx)),
                (STATUS_B, struct.pack("<HBBBBH", t.seq, t.pwm_left, t.pwm_right,
                                       t.dir_left | t.dir_right << 1, t.flags, t.free_ram)),
                (STATUS_C, struct.pack("<II", t.illegal_left, t.illegal_right)),
                (STATUS_D, struct.pack("<II", t.rejected, t.crc_rejected)),
                *([] if t.supply_dv is None else [(STATUS_F, struct.pack("<H6x", _sat16(t.supply_dv)))]),
                (STATUS_E, struct.pack("<HHHH", t.faults & 0xFFFF, _sat16(t.rx_lost), _sat16(t.late),
                                       (t.state or 0) & 0xFFFF))]
    reply: tuple[int, int, int, float] | None = None
    if isinstance(msg, Ack):
        reply = (KIND_ACK, 0, msg.seq, 0.0)
    elif isinstance(msg, Nak):
        reply = (KIND_NAK, _index(REASONS, msg.reason), msg.seq, 0.0)
    elif isinstance(msg, Error):
        reply = (KIND_ERR, _index(REASONS, msg.reason), 0, 0.0)
    elif isinstance(msg, Event):
        reply = (KIND_EVT, _index(EVENTS, msg.name), 0, 0.0)
    elif isinstance(msg, Param):
        reply = (KIND_PAR, PARAM_NAMES.index(msg.name), 0, msg.value)
    elif isinstance(msg, Hello):
        # the profile in force (boards with drive profiles) goes first: the reply ends the line
        return [*([] if msg.profile is None else [(HELLO_E, struct.pack("<B7x", msg.profile))]),
                (REPLY, struct.pack("<BBHI", KIND_HELLO, msg.version, _pack_version(msg.firmware_version),
                                    int(msg.build_id or "0", 16)))]
    elif isinstance(msg, Boot):
        reply = (KIND_BOOT, _index(BOOT_CAUSES, msg.cause), 0, 0.0)
    if reply is None:
        return []
    return [(REPLY, struct.pack("<BBHf", *reply))]


def _pack_version(text: str) -> int:
    """A firmware version ``major.minor.patch`` in 16 bits (6, 5, 5); 0 for none."""
    if not text:
        return 0
    major, minor, patch = (int(part) for part in text.split("."))
    if not (major < 64 and minor < 32 and patch < 32):
        raise CanCodecError(f"firmware version {text!r} does not fit 16 bits")
    return major << 10 | minor << 5 | patch


def _index(names: tuple[str, ...], name: str) -> int:
    return names.index(name) if name in names else 0


@dataclass
class TelemetryAssembler:
    """Chair-to-host frames back into the board's lines (``\\r\\n``-terminated bytes):
    a feedback line from its two frames, a TLM line from its five (0x312 to 0x315 and
    0x317, in that order: the line is complete at 0x317; 0x318 before 0x317 adds the
    supply), a ``HELLO:`` line from its reply (0x316; 0x319 just before it adds the
    drive profile in force)."""

    _enc: tuple[int, int] | None = None
    _status: dict[int, bytes] | None = None
    _profile: int | None = None

    def feed(self, can_id: int, data: bytes) -> bytes:
        """One chair-to-host frame; returns the line it completes (a REPLY frame is a
        line of its own), else ``b""``. Other frames are ignored."""
        if can_id == FEEDBACK_ENC:
            self._enc = struct.unpack("<ii", data[:8])
            return b""
        if can_id == FEEDBACK_VEL:
            if self._enc is None:
                return b""
            vl, vr, mode = struct.unpack("<hhB", data[:5])
            left, right = self._enc
            self._enc = None
            return (f"ENC:{left},{right},VEL:{_centi(vl)},{_centi(vr)},MODE:{MODES[mode]}\r\n"
                    .encode())
        if can_id in (STATUS_A, STATUS_B, STATUS_C, STATUS_D, STATUS_F):
            if can_id == STATUS_A:
                self._status = {}
            if self._status is not None:
                self._status[can_id] = bytes(data)
            return b""
        if can_id == STATUS_E:
            status, self._status = self._status, None
            if status is None or any(i not in status for i in (STATUS_A, STATUS_B, STATUS_C, STATUS_D)):
                return b""
            millis, rx = struct.unpack("<II", status[STATUS_A][:8])
            seq, pwm_l, pwm_r, dirs, flags, free = struct.unpack("<HBBBBH", status[STATUS_B][:8])
            ill_l, ill_r = struct.unpack("<II", status[STATUS_C][:8])
            rej, crc = struct.unpack("<II", status[STATUS_D][:8])
            faults, rx_lost, late, state = struct.unpack("<HHHH", data[:8])
            values = (millis, rx, seq, pwm_l, pwm_r, dirs & 1, dirs >> 1 & 1, ill_l, ill_r, flags,
                      rej, crc, free, faults, rx_lost, late, state)
            if STATUS_F in status:          # the supply (boards since it was measured)
                values += struct.unpack("<H", status[STATUS_F][:2])
            return b"TLM:" + b",".join(str(v).encode() for v in values) + b"\r\n"
        if can_id == HELLO_E:
            self._profile = data[0]
            return b""
        if can_id == REPLY:
            profile, self._profile = self._profile, None
            return _reply_line(data, profile)
        return b""


def _centi(value: int) -> str:
    sign = "-" if value < 0 else ""
    return f"{sign}{abs(value) // 100}.{abs(value) % 100:02d}"


def _reply_line(data: bytes, profile: int | None = None) -> bytes:
    """The line of a WC_REPLY frame; ``profile``: the WC_HELLO_E just before it, the
    last field of a ``HELLO:`` line that names the firmware's version."""
    kind, code, seq, value = struct.unpack("<BBHf", data[:8])
    if kind == KIND_ACK:
        return b"ACK:%d\r\n" % seq
    if kind == KIND_NAK:
        return b"NAK:%d,%s\r\n" % (seq, REASONS[code].encode())
    if kind == KIND_ERR:
        return b"ERR:%s\r\n" % REASONS[code].encode()
    if kind == KIND_EVT:
        return b"EVT:%s\r\n" % EVENTS[code].encode()
    if kind == KIND_PAR:
        name = PARAM_NAMES[code]
        text = str(round(value)) if name in INTEGER_PARAMS else f"{value:.4f}"
        return f"PAR:{name},{text}\r\n".encode()
    if kind == KIND_HELLO:
        build = struct.unpack("<I", data[4:8])[0]
        if seq == 0 and build == 0:
            return f"HELLO:{code},{FIRMWARE}\r\n".encode()
        version = f"{seq >> 10}.{seq >> 5 & 31}.{seq & 31}"
        tail = "" if profile is None else f",{profile}"
        return f"HELLO:{code},{FIRMWARE},{version},{build:08x}{tail}\r\n".encode()
    if kind == KIND_BOOT:
        cause = BOOT_CAUSES[code] if code < len(BOOT_CAUSES) else ""
        return f"BOOT:{FIRMWARE},{cause}\r\n".encode() if cause else f"BOOT:{FIRMWARE}\r\n".encode()
    return b""
