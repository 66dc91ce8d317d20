"""Lines the firmware sends: formatted whole, as ``LineBuffer`` does, then written.

The firmware writes a line only when the TX ring has room for all of it; with its
512-byte ring (``-DSERIAL_TX_BUFFER_SIZE=512``, firmware/final_control/Makefile) and
the per-tick limits that can never fail ("Output budget" in protocol/PROTOCOL.md), so
the port appends every line. That ``txDropped`` stays 0 is checked in the firmware
after every event of the differential runs (``wcdrive.hil.lockstep``).
"""

from __future__ import annotations

from wcdrive.avr.arduino_print import print_float, print_long, print_unsigned
from wcdrive.firmware.constants import ERR_LINES_PER_TICK, FIRMWARE_VERSION, MODE_NAMES, PROTOCOL_VERSION
from wcdrive.firmware.params import PARAMS
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import FAULT_NAMES

CRLF = b"\r\n"


def feedback_line(s: FirmwareState) -> bytes:
    """``ENC:<l>,<r>,VEL:<l>,<r>,MODE:<mode>``, the line every ``controlTick`` sends."""
    return b"".join((
        b"ENC:", print_long(s.encTickL), b",", print_long(s.encTickR),
        b",VEL:", print_float(s.rawVelL, 2), b",", print_float(s.rawVelR, 2),
        b",MODE:", MODE_NAMES[s.mode].encode(), CRLF,
    ))


def send_event(what: str) -> bytes:
    """``sendEvent``: ``EVT:<what>``."""
    return b"EVT:" + what.encode() + CRLF


def send_fault_events(faults: int) -> bytes:
    """``sendFaultEvents``: one ``EVT:FAULT,<name>`` line per fault bit set."""
    return b"".join(b"EVT:FAULT," + name.encode() + CRLF
                    for i, name in enumerate(FAULT_NAMES) if faults & (1 << i))


def send_telemetry(s: FirmwareState, now: int) -> bytes:
    """``TLM:`` (protocol v2), sent after each feedback line once a host said hello."""
    flags = ((1 if s.watchdogArmed else 0) | (2 if s.emergencyStop else 0)
             | (4 if s.estopLatched else 0) | (8 if s.ppmLost else 0) | (16 if s.parked else 0)
             | ((s.pivotPhase << 5) & 0xFF) | (128 if s.faultFlags else 0))
    # Every field is unsigned and in range, so %d prints what Print::print prints.
    return b"TLM:%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d\r\n" % (
        now, s.rxCount, s.lastSeq, s.pwmL, s.pwmR, s.dirL, s.dirR, s.illTickL, s.illTickR,
        flags, s.rejectedCount, s.crcRejected, s.freeRam, s.faultFlags)


DATA_NONE, DATA_HELLO, DATA_PARAM = 0, 1, 2


def answer(s: FirmwareState, reason: str | None, seq: int, data: int, param: int,
           out: bytearray) -> None:
    """One command's answer: a data line (HELLO/PAR), then ``ACK:``/``NAK:`` for a framed
    line with a sequence number (``seq >= 0``), ``ERR:`` for other rejected commands. At
    most ERR_LINES_PER_TICK commands are answered per tick; the rest are counted."""
    if s.errLinesThisTick >= ERR_LINES_PER_TICK:
        s.errSuppressed = (s.errSuppressed + 1) & 0xFFFFFFFF
        return
    s.errLinesThisTick += 1
    if reason is None and data == DATA_HELLO:
        out += b"HELLO:%d,final_control,%s,%s\r\n" % (PROTOCOL_VERSION, FIRMWARE_VERSION.encode(),
                                                        s.buildId.encode())
    elif reason is None and data == DATA_PARAM:
        p = PARAMS[param]
        value = getattr(s, p.field)
        text = print_unsigned(value) if p.integer else print_float(value, 4)
        out += b"PAR:" + p.name.encode() + b"," + text + CRLF
    if seq >= 0:
        if reason is None:
            out += b"ACK:%d\r\n" % seq
        else:
            out += b"NAK:%d,%s\r\n" % (seq, reason.encode())
    elif reason is not None:
        out += b"ERR:" + reason.encode() + CRLF


def reject(s: FirmwareState, reason: str, out: bytearray) -> None:
    """Counts a malformed command and reports it."""
    s.rejectedCount = (s.rejectedCount + 1) & 0xFFFFFFFF
    answer(s, reason, -1, DATA_NONE, 0, out)
