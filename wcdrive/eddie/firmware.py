"""The Eddie control board's firmware as a pure, deterministic model: ``EddieFirmware``
takes the bytes the board receives (``feed``) and returns its replies, and runs one
20 ms Position Controller pass a ``tick``, given the wheels' positions, returning the
motor powers.

Derived line by line from Parallax's Spin source of the Eddie control board firmware
(``Eddie.spin``, Propeller Tool archive of 2011-12-19, VERSION 12 before a third
party's +100; public at github.com/robotictang/eddiebot_firmware) and its motor
driver (``Eddie Motor Driver.spin``). No Propeller emulator was built: this is a port
by reading, and docs/eddie.md lists what the source leaves open.

The model is four modules, each saying what it keeps from the source, and every
name is importable from here too: the line buffer is here; the parser, the commands
and their replies in ``command_interpreter`` (``CommandInterpreter``, ``ParseError``,
``EddieInputs``); the Position Controller loop in ``position_controller``
(``PositionController``, ``Wheel``, the modes); Spin's integer arithmetic in
``spin_arithmetic``. The line buffer keeps:

* 255 bytes (``BUFFER_LENGTH``): bytes are stored until CR; BS removes itself and the
  byte before; a bare CR gets no answer at all; the 255th byte without a CR answers
  ``ERROR`` once the next CR arrives, and that line is dropped;
* control characters (LF among them) are *stored*, as the source's empty ``case``
  branch does, so ``eol="firmware"`` makes ``"DIST\\r\\n"`` poison the next command.
  ``eol="tolerant"`` is the other reading: LF ends a line, and an LF right after a CR
  is dropped (docs/eddie.md says why both exist).
"""

from __future__ import annotations

from wcdrive.eddie.command_interpreter import (
    ERR_COMMAND,
    ERR_ENCODER,
    ERR_FEW,
    ERR_MANY,
    ERR_OVERFLOW,
    ERR_PARAMETER,
    HT,
    INITIAL_GPIO,
    INITIAL_PING,
    MAX_WATCH_SECONDS,
    OUTPUTABLE,
    PING_MAX,
    PING_MIN,
    PING_SHIFT,
    PING_WAIT_S,
    PINGABLE,
    STOP_WAIT_S,
    VERSION,
    CommandInterpreter,
    EddieInputs,
    ParseError,
)
from wcdrive.eddie.position_controller import (
    DEADZONE,
    DEFAULT_POS_ACCEL,
    DIVISOR,
    HISTORY,
    KP,
    MAX_ON_TIME,
    MAX_POW_ACCEL,
    MODE_NAMES,
    POSITION,
    POSITIONS_PER_ROTATION,
    POWER,
    STOPPING,
    VELOCITY,
    PositionController,
    Wheel,
)
from wcdrive.eddie.spin_arithmetic import CLKFREQ, clamp, hexw, s32, sdiv, smod, ssqrt, sx8, sx16

__all__ = ["BS", "BUFFER_LENGTH", "CLKFREQ", "CR", "DEADZONE", "DEFAULT_POS_ACCEL", "DIVISOR",
           "ERR_COMMAND", "ERR_ENCODER", "ERR_FEW", "ERR_MANY", "ERR_OVERFLOW", "ERR_PARAMETER",
           "HISTORY", "HT", "INITIAL_GPIO", "INITIAL_PING", "KP", "LF", "MAX_ON_TIME", "MAX_POW_ACCEL",
           "MAX_WATCH_SECONDS", "MODE_NAMES", "OUTPUTABLE", "PINGABLE", "PING_MAX", "PING_MIN",
           "PING_SHIFT", "PING_WAIT_S", "POSITION", "POSITIONS_PER_ROTATION", "POWER", "STOPPING",
           "STOP_WAIT_S", "VELOCITY", "VERSION", "CommandInterpreter", "EddieFirmware", "EddieInputs",
           "ParseError", "PositionController", "Wheel", "clamp", "hexw", "s32", "sdiv", "smod", "ssqrt",
           "sx8", "sx16"]

BUFFER_LENGTH = 255

CR, LF, BS = 0x0D, 0x0A, 0x08


class EddieFirmware(CommandInterpreter):
    """The board: ``feed(data)`` takes received bytes and returns the reply bytes;
    ``tick(left, right)`` is one 20 ms Position Controller iteration given the wheels'
    positions (forward positive), returning the motor powers (-7520..7520).
    ``ticks`` counts them (the ``WATCH`` timer)."""

    def __init__(self, *, eol: str = "firmware", hw_version: int = 0x0001, version: int = VERSION,
                 speed_of_sound: float = 343.0) -> None:
        if eol not in ("firmware", "tolerant"):
            raise ValueError("eol must be 'firmware' or 'tolerant'")
        super().__init__(hw_version=hw_version, version=version, speed_of_sound=speed_of_sound)
        self.eol = eol
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
