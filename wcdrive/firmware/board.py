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
#: What ``measureFreeRam()`` reports on the Mega build (bytes between the heap and the
#: stack in loop()); the simulated board reports it too. tests/test_protocol.py checks it
#: against the ELF running in simavr, so a firmware change that moves it fails there.
FREE_RAM = 6987


class Firmware:
    def __init__(self, state: FirmwareState | None = None, *, boot_millis: int = 0) -> None:
        """A board just out of ``setup()`` (which ends with ``lastControlTime =
        millis()``), or one in any given ``state``."""
        self.state = state if state is not None else FirmwareState(lastControlTime=boot_millis)
        self.free_ram = FREE_RAM

    @staticmethod
    def boot_output() -> bytes:
        return BOOT_LINE

    def feed(self, data: bytes) -> bytes:
        out = bytearray()
        process_bytes(self.state, data, out)
        return bytes(out)

    def due(self, now: int) -> bool:
        return ((now - self.state.lastControlTime) & 0xFFFFFFFF) >= CONTROL_PERIOD_MS

    def tick(self, now: int, count_l: int, count_r: int, illegal_l: int = 0, illegal_r: int = 0,
             free_ram: int | None = None) -> bytes:
        """``controlTick(now)``. The latched counts are inputs, and so is ``free_ram``
        (what loop() measured before the tick; None: ``self.free_ram``, which starts at
        the figure of the Mega build, ``FREE_RAM``)."""
        self.state.freeRam = self.free_ram if free_ram is None else free_ram
        out = bytearray()
        control_tick(self.state, now, count_l, count_r, out, illegal_l, illegal_r)
        return bytes(out)
