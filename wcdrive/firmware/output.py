"""Lines the firmware sends: formatted whole, as ``LineBuffer`` does, then written
through ``send`` (``LineBuffer::send``), which keeps the output budget: a line goes
only if it fits ``txCredit``, which each control tick refills by ``TX_CREDIT_PER_MS`` a
millisecond up to ``TX_CREDIT_MAX``; one that does not fit is counted in ``txDropped``.
The budget is below what the UART drains, so the firmware's TX ring never fills and
the same lines are dropped on both sides ("Output budget" in protocol/PROTOCOL.md).
"""

from __future__ import annotations

from wcdrive.avr.arduino_print import print_float, print_long, print_unsigned
from wcdrive.avr.f32 import add, mul, to_u32
from wcdrive.firmware import constants as C
from wcdrive.firmware.constants import (
    ERR_LINES_PER_TICK,
    FIRMWARE_VERSION,
    MODE_NAMES,
    PROTOCOL_VERSION,
    PROTOCOL_VERSION_PLAIN,
    TX_CREDIT_MAX,
    TX_CREDIT_PER_MS,
)
from wcdrive.firmware.params import PARAMS
from wcdrive.firmware.state import FirmwareState
from wcdrive.protocol.codec import FAULT_NAMES, board_frame

CRLF = b"\r\n"


def send(s: FirmwareState, line: bytes, out: bytearray) -> None:
    """``LineBuffer::send``: ``line`` (ending in ``\r\n``; framed first after
    ``hello:4``, ``frameLine``) goes out if the output budget has room for it, else it is
    counted in ``txDropped``; the line counter counts the framed lines that go. (The
    sketch's second guard, a full TX ring, ``txRingFull``, cannot happen within the
    budget; the differential runs check that.)"""
    if s.linesFramed:
        line = board_frame(line[:-2], s.lineCounter)
    if len(line) > s.txCredit:
        s.txDropped = (s.txDropped + 1) & 0xFFFFFFFF
    else:
        s.txCredit -= len(line)
        out += line
        if s.linesFramed:
            s.lineCounter = (s.lineCounter + 1) & 0xFF


def refill_credit(s: FirmwareState, elapsed: int) -> None:
    """The control tick's refill of the output budget, ``elapsed`` ms after the last."""
    if elapsed >= TX_CREDIT_MAX // TX_CREDIT_PER_MS:
        s.txCredit = TX_CREDIT_MAX
    else:
        s.txCredit = min(TX_CREDIT_MAX, s.txCredit + elapsed * TX_CREDIT_PER_MS)


def feedback_line(s: FirmwareState) -> bytes:
    """``ENC:<l>,<r>,VEL:<l>,<r>,MODE:<mode>``, the line every ``controlTick`` sends;
    with ``feedbackForm`` 1 and the lines unframed, ``,r<p|n><|vel r|>,l<p|n><|vel l|>``
    follows ``MODE`` (``wheel_tail``).

    The tail is for hosts that never say ``hello:4`` (a ros2_control hardware interface
    written for the seed-era board); a framed line stays as it was, so the worst tick
    of a v4 host still fits the output budget."""
    tail = wheel_tail(s) if s.feedbackForm and not s.linesFramed else b""
    return b"".join((
        b"ENC:", print_long(s.encTickL), b",", print_long(s.encTickR),
        b",VEL:", print_float(s.rawVelL, 2), b",", print_float(s.rawVelR, 2),
        b",MODE:", MODE_NAMES[s.mode].encode(), tail, CRLF,
    ))


def wheel_tail(s: FirmwareState) -> bytes:
    """The tail ``controlTick`` prints in ``feedback_form`` 1:
    ``,r<p|n><|rawVelR|>,l<p|n><|rawVelL|>``, the right wheel first as in the commands
    ``rp5.0,lp3.0,``; rad/s, forward positive."""
    return print_wheel(b",r", s.rawVelR) + print_wheel(b",l", s.rawVelL)


def print_wheel(label: bytes, v: float) -> bytes:
    r"""``printWheel``: ``<label><p|n><|v|>``, the magnitude printed as ``VEL`` prints it
    (2 decimals).

    The sign is a letter (``n`` below zero, else ``p``) and the number has none, so a
    plugin that reads ``r([pn])-?(\d*\.?\d+)`` takes the whole magnitude."""
    return label + (b"n" if v < 0 else b"p") + print_float(abs(v), 2)


def send_event(what: str) -> bytes:
    """``sendEvent``: ``EVT:<what>``."""
    return b"EVT:" + what.encode() + CRLF


def send_fault_events(s: FirmwareState, faults: int, out: bytearray) -> None:
    """``sendFaultEvents``: one ``EVT:FAULT,<name>`` line per fault bit set."""
    for i, name in enumerate(FAULT_NAMES):
        if faults & (1 << i):
            send(s, b"EVT:FAULT," + name.encode() + CRLF, out)


def send_telemetry(s: FirmwareState, now: int) -> bytes:
    """``TLM:`` (protocol v2), sent after each feedback line once a host said hello."""
    flags = ((1 if s.watchdogArmed else 0) | (2 if s.emergencyStop else 0)
             | (4 if s.estopLatched else 0) | (8 if s.ppmLost else 0) | (16 if s.parked else 0)
             | ((s.pivotPhase << 5) & 0xFF) | (128 if s.faultFlags else 0))
    engaged = s.inhibitStable | s.inhibitLatched
    state = ((1 if s.needNeutral else 0) | (2 if s.neutralFault else 0)
             | (4 if engaged & C.INHIBIT_STOP_MASK else 0) | (8 if engaged & ~C.INHIBIT_STOP_MASK & 7 else 0)
             | (16 if s.brakeFitted and not s.brakeReleased else 0) | (32 if engaged & C.INHIBIT_PUSH else 0)
             | (64 if s.thermalRollback else 0) | (128 if s.batteryLow else 0) | (s.profile << 8))
    # the filtered supply in tenths of a volt, rounded (``supplyDecivolts``)
    supply = to_u32(add(mul(s.supplyVolts, 10.0), 0.5))
    # Every field is unsigned and in range, so %d prints what Print::print prints.
    return b"TLM:%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d\r\n" % (
        now, s.rxCount, s.lastSeq, s.pwmL, s.pwmR, s.dirL, s.dirR, s.illTickL, s.illTickR,
        flags, s.rejectedCount, s.crcRejected, s.freeRam, s.faultFlags, s.rxLostTick, s.lateTicks,
        state, supply)


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
        version = PROTOCOL_VERSION if s.linesFramed else PROTOCOL_VERSION_PLAIN
        send(s, b"HELLO:%d,final_control,%s,%s,%d\r\n" % (version, FIRMWARE_VERSION.encode(),
                                                           s.buildId.encode(), s.profile), out)
    elif reason is None and data == DATA_PARAM:
        p = PARAMS[param]
        value = getattr(s, p.field)
        text = print_unsigned(value) if p.integer else print_float(value, 4)
        send(s, b"PAR:" + p.name.encode() + b"," + text + CRLF, out)
    if seq >= 0:
        if reason is None:
            send(s, b"ACK:%d\r\n" % seq, out)
        else:
            send(s, b"NAK:%d,%s\r\n" % (seq, reason.encode()), out)
    elif reason is not None:
        send(s, b"ERR:" + reason.encode() + CRLF, out)


def reject(s: FirmwareState, reason: str, out: bytearray) -> None:
    """Counts a malformed command and reports it."""
    s.rejectedCount = (s.rejectedCount + 1) & 0xFFFFFFFF
    answer(s, reason, -1, DATA_NONE, 0, out)
