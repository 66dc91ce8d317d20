"""``Firmware``: the port of final_control as one object with explicit inputs.

The firmware's ``loop()`` does two things, and so does this class:

* ``feed(data)``: bytes read from the UART, each through ``processByte``;
* ``tick(now, count_l, count_r)``: ``controlTick(now)`` with the encoder counts it
  latched.

``due(now)`` says whether a loop pass at ``millis() == now`` runs a tick. Every call
returns the bytes the firmware sends for it, and the whole state is ``state``.
"""

from __future__ import annotations

from wcdrive.firmware.commands import process_bytes
from wcdrive.firmware.constants import CONTROL_PERIOD_MS
from wcdrive.firmware.control import control_tick
from wcdrive.firmware.state import FirmwareState

BOOT_LINE = b"BOOT:final_control\r\n"


class Firmware:
    def __init__(self, state: FirmwareState | None = None, *, boot_millis: int = 0) -> None:
        """A board just out of ``setup()`` (which ends with ``lastControlTime =
        millis()``), or one in any given ``state``."""
        self.state = state if state is not None else FirmwareState(lastControlTime=boot_millis)

    @staticmethod
    def boot_output() -> bytes:
        return BOOT_LINE

    def feed(self, data: bytes) -> bytes:
        out = bytearray()
        process_bytes(self.state, data, out)
        return bytes(out)

    def due(self, now: int) -> bool:
        return ((now - self.state.lastControlTime) & 0xFFFFFFFF) >= CONTROL_PERIOD_MS

    def tick(self, now: int, count_l: int, count_r: int) -> bytes:
        out = bytearray()
        control_tick(self.state, now, count_l, count_r, out)
        return bytes(out)
