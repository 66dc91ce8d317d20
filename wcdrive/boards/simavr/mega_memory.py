"""The memory of a running Mega by the firmware's names: ``read_symbols`` gives the
ELF's globals (data-space address and size) and functions (flash address);
``MegaMemory`` reads and writes the data space (SRAM and I/O registers), a global by
name decoded by its C type (``VARIABLE_FORMATS``), the EEPROM, the stack pointer and
the free RAM.

``MegaMemory`` is a base of ``VirtualMega`` and holds no state of its own: the board
gives it the harness (``_c``, its handle ``_s``) and the ELF's symbols
(``variables``). Reads and writes go through the harness at once, between runs, so
they see and change what the firmware will see next; nothing is cached.
"""

from __future__ import annotations

import ctypes
import struct
from pathlib import Path

from elftools.elf.elffile import ELFFile
from elftools.elf.sections import SymbolTableSection

from wcdrive.boards.simavr.harness_binding import HarnessError

SRAM_OFFSET = 0x800000

#: C types of the controller globals, for ``read(name)``.
VARIABLE_FORMATS = {
    "f": ("targetL", "targetR", "setpointL", "setpointR", "rawVelL", "rawVelR", "filtVelL",
          "filtVelR", "integralL", "integralR", "prevMeasL", "prevMeasR", "outputL", "outputR",
          "lastTravel", "pendingL", "pendingR", "kpL", "kiL", "kdL", "kpR", "kiR", "kdR",
          "maxWheel", "maxAccel", "estopDecel", "effortSpeedL", "effortSpeedR", "effortSetpointL",
          "effortSetpointR", "overspeedFromL", "overspeedFromR", "haltIntegralL", "haltIntegralR",
          "haltSetpointL", "haltSetpointR", "windingTempL", "windingTempR", "supplyVolts", "fwdSpeed",
          "revSpeed", "driveAccel", "driveDecel", "turnSpeed", "turnAccel", "turnAtSpeed", "stallTimeout",
          "stallTime", "tremorDamping", "dampedL", "dampedR"),
    "i": ("encoderValueL", "encoderValueR", "encTickL", "encTickR", "prevEncL", "prevEncR", "holdRefL",
          "holdRefR", "holdStepL", "holdStepR"),
    "I": ("illegalL", "illegalR", "lastControlTime", "tickCount", "lastCmdTime", "rejectedCount",
          "errSuppressed", "txDropped", "timer0_millis", "timer0_overflow_count", "illTickL",
          "illTickR", "rxCount", "crcRejected", "txRingFull", "rxGaps", "rxLost", "rxLostTick",
          "lastTickTime", "lateTicks"),
    "H": ("freeRam", "watchdogMs", "lastSeq", "faultFlags", "txCredit", "supplyTick", "currentTickL",
          "currentTickR", "adcCurrentL", "adcCurrentR"),
    "B": ("mode", "pwmL", "pwmR", "dirL", "dirR", "pivotPhase", "pivotTicksLeft", "cmdSinceTick",
          "watchdogArmed", "emergencyStop", "ppmLost", "stillTicks", "parked", "cmdLen",
          "cmdCommas", "cmdDiscarding", "errLinesThisTick", "lastEncodedL", "lastEncodedR",
          "timer0_fract", "estopLatched", "tlmEnabled", "linesFramed", "lineCounter", "unframedLine",
          "stormTickL", "stormTickR",
          "stallTicksL", "stallTicksR", "reverseTicksL", "reverseTicksR", "runawayTicksL",
          "runawayTicksR", "stormL", "stormR",
          "resetCause", "effortPwmL", "effortPwmR", "effortTicksL", "effortTicksR", "eeNext", "eeBusy",
          "holding", "holdRollaway", "brakeReleased", "overspeedTicksL", "overspeedTicksR",
          "limitLatched", "feedbackForm", "needNeutral", "neutralSeen", "neutralTicks", "notNeutralSent",
          "notNeutralPending", "notNeutralTicks", "neutralFault", "inhibitTick", "inhibitStable",
          "inhibitCountL", "inhibitCountR", "inhibitLatched", "inhibitPending",
          "inhibitOn", "inhibitCountP",
          "brakeFitted", "profile", "brakePhase", "brakeTicks", "brakeStatusTick", "brakeStatusTicks",
          "thermalRollback", "thermalPending", "batteryLow", "batteryPending"),
}
_FORMAT_OF = {name: fmt for fmt, names in VARIABLE_FORMATS.items() for name in names}


def read_symbols(elf_path: Path) -> tuple[dict[str, tuple[int, int]], dict[str, int]]:
    """``(variables, functions)``: data-space address and size by name, flash byte address by name."""
    variables: dict[str, tuple[int, int]] = {}
    functions: dict[str, int] = {}
    with open(elf_path, "rb") as handle:
        elf = ELFFile(handle)
        for section in elf.iter_sections():
            if not isinstance(section, SymbolTableSection):
                continue
            for sym in section.iter_symbols():
                kind = sym["st_info"]["type"]
                value = sym["st_value"]
                if kind in ("STT_OBJECT", "STT_NOTYPE") and value >= SRAM_OFFSET:
                    variables[sym.name] = (value - SRAM_OFFSET, sym["st_size"])
                elif kind == "STT_FUNC":
                    functions[sym.name] = value
    return variables, functions


class MegaMemory:
    """Data space, globals, EEPROM and stack of the Mega a ``VirtualMega`` runs."""

    _c: ctypes.CDLL
    _s: int | None
    variables: dict[str, tuple[int, int]]

    def read_bytes(self, address: int, size: int) -> bytes:
        """``size`` bytes of data space (SRAM and I/O registers) from ``address``."""
        buf = (ctypes.c_uint8 * size)()
        if self._c.wcsim_read(self._s, address, buf, size) != 0:
            raise ValueError(f"address {address:#x}+{size} is outside the data space")
        return bytes(buf)

    def write_bytes(self, address: int, data: bytes) -> None:
        """Writes ``data`` into data space (SRAM and I/O registers) at ``address``: for
        tests that corrupt what a fault would (a stack, a register)."""
        buf = (ctypes.c_uint8 * len(data))(*data)
        if self._c.wcsim_write(self._s, address, buf, len(data)) != 0:
            raise ValueError(f"address {address:#x}+{len(data)} is outside the data space")

    # ---- EEPROM --------------------------------------------------------------------
    @property
    def eeprom_size(self) -> int:
        """Bytes of EEPROM (4096 on the Mega 2560)."""
        return int(self._c.wcsim_eeprom_size(self._s))

    def read_eeprom(self, address: int = 0, size: int | None = None) -> bytes:
        """The EEPROM's contents from ``address`` (all of it by default). simavr makes it
        erased (0xFF) and keeps it across ``reset`` of any cause, as the chip does."""
        size = self.eeprom_size - address if size is None else size
        buf = (ctypes.c_uint8 * size)()
        if self._c.wcsim_eeprom_read(self._s, address, buf, size) != 0:
            raise ValueError(f"EEPROM address {address:#x}+{size} is outside the EEPROM")
        return bytes(buf)

    def write_eeprom(self, data: bytes, address: int = 0) -> None:
        """Writes ``data`` into the EEPROM at ``address`` at once (as a programmer would,
        no write cycle): to preload an image before the firmware boots, or corrupt one."""
        buf = (ctypes.c_uint8 * len(data))(*data)
        if self._c.wcsim_eeprom_write(self._s, address, buf, len(data)) != 0:
            raise ValueError(f"EEPROM address {address:#x}+{len(data)} is outside the EEPROM")

    def address_of(self, name: str) -> tuple[int, int]:
        """Data-space address and size of a firmware global, from the ELF's symbols."""
        try:
            return self.variables[name]
        except KeyError:
            raise KeyError(f"the ELF has no variable {name!r}") from None

    def snapshot(self, names: tuple[str, ...]) -> dict[str, float | int]:
        """Several globals at once (one read of the SRAM span that holds them)."""
        spans = [self.address_of(n) for n in names]
        lo = min(a for a, _ in spans)
        hi = max(a + size for a, size in spans)
        block = self.read_bytes(lo, hi - lo)
        out: dict[str, float | int] = {}
        for name, (address, size) in zip(names, spans, strict=True):
            raw = block[address - lo:address - lo + size]
            out[name] = struct.unpack("<" + _FORMAT_OF[name], raw)[0]
        return out

    def read_raw(self, name: str) -> bytes:
        """The bytes of a firmware global by name."""
        address, size = self.address_of(name)
        return self.read_bytes(address, size)

    def read(self, name: str, fmt: str | None = None) -> float | int:
        """A firmware global by name, decoded by its C type (floats as Python floats
        holding the exact binary32 value); ``fmt`` is a struct code for other globals."""
        fmt = fmt or _FORMAT_OF.get(name)
        if fmt is None:
            raise KeyError(f"no known C type for {name!r}; pass fmt or use read_raw()")
        return struct.unpack("<" + fmt, self.read_raw(name)[:struct.calcsize(fmt)])[0]

    def write(self, name: str, value: float | int, fmt: str | None = None) -> None:
        """Writes a firmware global by name, encoded by its C type (or ``fmt``)."""
        data = struct.pack("<" + (fmt or _FORMAT_OF[name]), value)
        self.write_raw(name, data)

    def write_raw(self, name: str, data: bytes) -> None:
        """Writes bytes into a firmware global by name (at most its size)."""
        address, size = self.address_of(name)
        if len(data) > size:
            raise ValueError(f"{len(data)} bytes do not fit in {name} ({size} bytes)")
        buf = (ctypes.c_uint8 * len(data))(*data)
        self._c.wcsim_write(self._s, address, buf, len(data))

    def stack_pointer(self) -> int:
        """The AVR's stack pointer now."""
        return int(self._c.wcsim_sp(self._s))

    def free_ram(self) -> int:
        """Bytes between the end of .bss (no heap is used) and the stack pointer."""
        if "__bss_end" not in self.variables:
            raise HarnessError("the ELF has no __bss_end symbol")
        return self.stack_pointer() - self.variables["__bss_end"][0]
