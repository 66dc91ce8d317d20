"""Lines the firmware sends: formatted whole, as ``LineBuffer`` does, then written.

The firmware writes a line only when the TX ring has room for all of it; with its
256-byte ring and the per-tick limits that can never fail (docs/protocol), so the
port appends every line. ``txDropped`` staying 0 is checked against the firmware.
"""

from __future__ import annotations

from wcdrive.firmware.arduino_print import print_float, print_long
from wcdrive.firmware.constants import ERR_LINES_PER_TICK, MODE_NAMES
from wcdrive.firmware.state import FirmwareState

CRLF = b"\r\n"


def feedback_line(s: FirmwareState) -> bytes:
    return b"".join((
        b"ENC:", print_long(s.encTickL), b",", print_long(s.encTickR),
        b",VEL:", print_float(s.rawVelL, 2), b",", print_float(s.rawVelR, 2),
        b",MODE:", MODE_NAMES[s.mode].encode(), CRLF,
    ))


def event_line(what: str) -> bytes:
    return b"EVT:" + what.encode() + CRLF


def reject(s: FirmwareState, reason: str, out: bytearray) -> None:
    """Counts a malformed command and reports it, at most ERR_LINES_PER_TICK a tick."""
    s.rejectedCount = (s.rejectedCount + 1) & 0xFFFFFFFF
    if s.errLinesThisTick >= ERR_LINES_PER_TICK:
        s.errSuppressed = (s.errSuppressed + 1) & 0xFFFFFFFF
        return
    s.errLinesThisTick += 1
    out += b"ERR:" + reason.encode() + CRLF
