"""A Mega 2560 as it leaves the factory: the real stk500v2 bootloader in its boot
section, whatever program avrdude wrote below it, and no ELF.

``BootloaderMega`` is a ``VirtualMega`` whose flash comes from Intel HEX files (the
bootloader, ``stk500boot_v2_mega2560.hex`` from Debian's arduino-core-avr, unmodified)
instead of an ELF. The reset vector is the bootloader's (BOOTRST programmed, as the
Arduino fuses set it): after every reset the bootloader runs, talks stk500v2 on
USART0 for about 0.8 s, and then jumps to the program at address 0. Bytes sent to it
wait until the USART's receive FIFO has room (``wcsim_feed``: the XON side of
simavr's UART), so none is lost while the bootloader writes a page.

    mega = BootloaderMega(flash_file="mega.flash")   # kept across runs when given
    mega.reset()                                      # DTR
    mega.send(b"...")                                  # avrdude's bytes
    mega.run_for(1.0)
    mega.in_bootloader                                 # False once it left for the program
    mega.save_flash()                                  # also done by close()

``BootloaderBoard`` runs one behind a ``MegaBoard``'s thread with the chair on its pins
(``wcdrive pty --avr --bootloader``), paced to the wall clock while the bootloader
runs (avrdude's timeouts and the bootloader's are in real seconds), and after that at
``speed`` or flat out, as chosen.
"""

from __future__ import annotations

import ctypes
import time
from pathlib import Path

from wcdrive.avr.timer0 import F_CPU
from wcdrive.boards.current_sense import CURRENT_CHANNELS
from wcdrive.boards.current_sense import ZERO_MV as CURRENT_ZERO_MV
from wcdrive.boards.simavr.mega_board import MegaBoard
from wcdrive.boards.simavr.virtual_mega import ENCODER_PINS, HarnessError, Reset, VirtualMega, _lib
from wcdrive.boards.supply_sense import NOMINAL_MV, SUPPLY_CHANNEL
from wcdrive.errors import WcdriveFileError
from wcdrive.plant import ChairParams

__all__ = ["BOOTLOADER_HEX", "BOOT_START", "BootloaderBoard", "BootloaderMega", "HexError",
           "parse_ihex"]

#: The Arduino Mega 2560's bootloader as Debian's arduino-core-avr ships it.
BOOTLOADER_HEX = Path("/usr/share/arduino/hardware/arduino/avr/bootloaders/stk500v2/"
                      "stk500boot_v2_mega2560.hex")
#: The boot section's first byte (BOOTSZ = 4096 words, the Mega's fuses): the reset
#: vector with BOOTRST programmed.
BOOT_START = 0x3E000
FLASH_SIZE = 0x40000


class HexError(WcdriveFileError):
    """An Intel HEX file that cannot be read."""


def parse_ihex(text: str) -> dict[int, bytes]:
    """The data of an Intel HEX file (records 00, 01, 02, 04; 03 and 05 ignored) as
    contiguous runs: ``{start address: bytes}``. Checksums are checked."""
    memory: dict[int, int] = {}
    base = 0
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line:
            continue
        try:
            if not line.startswith(":"):
                raise ValueError("no ':'")
            record = bytes.fromhex(line[1:])
        except ValueError as exc:
            raise HexError(f"line {number}: not an Intel HEX record ({exc})") from None
        if len(record) < 5 or len(record) != record[0] + 5:
            raise HexError(f"line {number}: wrong length")
        if sum(record) & 0xFF:
            raise HexError(f"line {number}: bad checksum")
        count, address, kind = record[0], (record[1] << 8) | record[2], record[3]
        data = record[4:4 + count]
        if kind == 0:
            for i in range(count):
                memory[base + address + i] = data[i]
        elif kind == 1:
            break
        elif kind == 2:
            base = int.from_bytes(data, "big") << 4
        elif kind == 4:
            base = int.from_bytes(data, "big") << 16
    runs: dict[int, bytes] = {}
    start = None
    buf = bytearray()
    for addr in sorted(memory):
        if start is not None and addr == start + len(buf):
            buf.append(memory[addr])
            continue
        if start is not None:
            runs[start] = bytes(buf)
        start, buf = addr, bytearray([memory[addr]])
    if start is not None:
        runs[start] = bytes(buf)
    return runs


class BootloaderMega(VirtualMega):
    """An ATmega2560 with the stk500v2 bootloader and BOOTRST; no ELF, so no symbols
    (``read(name)`` and the hooks are for ELF-built boards)."""

    def __init__(self, *, flash_file: str | Path | None = None,
                 bootloader: str | Path = BOOTLOADER_HEX, program: str | Path | None = None) -> None:
        """``flash_file``: the whole flash, read at start when it exists and written by
        ``save_flash``/``close`` (the chip keeps its program across runs).
        ``program``: a HEX written below the bootloader at start (as if flashed)."""
        self.elf = None  # type: ignore[assignment]
        self.variables, self.functions = {}, {}
        self._c = _lib()
        self._declare()
        err = ctypes.create_string_buffer(256)
        handle = self._c.wcsim_new_chip(b"atmega2560", F_CPU, err, len(err))
        if not handle:
            raise HarnessError(err.value.decode())
        self._s = handle
        self._hook_names = []
        self._uart_free_at = 0
        self._closed_cycle = 0
        self._pin_level = {}
        self._analog = {}
        self.tx_log = []
        self.keep_records = True
        self.hit_log = []
        self.rx_wire = []
        self.rx_lost = []
        self.resets = []
        self._resets_taken = 0
        self._vcd = False
        self.flash_file = Path(flash_file) if flash_file is not None else None
        if self.flash_file is not None and self.flash_file.exists():
            image = self.flash_file.read_bytes()
            if len(image) != FLASH_SIZE:
                raise HarnessError(f"{self.flash_file} is not a {FLASH_SIZE}-byte flash image")
            self.write_flash(0, image)
        else:
            self.load_hex(Path(bootloader).read_text())
        if program is not None:
            self.load_hex(Path(program).read_text())
        self._c.wcsim_set_reset_pc(self._s, BOOT_START)
        self._collect_resets()
        for side in ENCODER_PINS:
            for pin in ENCODER_PINS[side]:
                self.set_pin(pin, 1, at=0)
        # The program flashed may read the supply sense: a 24 V battery, as VirtualMega's.
        self.set_analog(SUPPLY_CHANNEL, NOMINAL_MV, at=0)
        for channel in CURRENT_CHANNELS.values():
            self.set_analog(channel, CURRENT_ZERO_MV, at=0)

    def _declare(self) -> None:
        p, u32, i32, sz = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_int, ctypes.c_size_t
        u8p = ctypes.POINTER(ctypes.c_uint8)
        for name, restype, argtypes in (
                ("wcsim_new_chip", p, [ctypes.c_char_p, u32, ctypes.c_char_p, i32]),
                ("wcsim_flash_write", i32, [p, u32, u8p, u32]),
                ("wcsim_flash_read", i32, [p, u32, u8p, u32]),
                ("wcsim_set_reset_pc", None, [p, u32]),
                ("wcsim_pc", u32, [p]),
                ("wcsim_feed", i32, [p, u8p, sz]),
                ("wcsim_feed_pending", sz, [p]),
                ("wcsim_feed_clear", None, [p]),
                ("wcsim_run_fed", i32, [p, ctypes.c_uint64])):
            fn = getattr(self._c, name)
            fn.restype, fn.argtypes = restype, argtypes

    # ---- flash ---------------------------------------------------------------------
    def load_hex(self, text: str) -> None:
        """Writes an Intel HEX file's data into flash (as a programmer would)."""
        for start, data in parse_ihex(text).items():
            self.write_flash(start, data)

    def write_flash(self, address: int, data: bytes) -> None:
        """Writes ``data`` into flash at byte ``address`` (as a programmer would)."""
        buf = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
        if self._c.wcsim_flash_write(self._s, address, buf, len(data)) != 0:
            raise ValueError(f"flash {address:#x}+{len(data)} is outside the chip's flash")

    def read_flash(self, address: int = 0, size: int = FLASH_SIZE) -> bytes:
        """``size`` bytes of flash from byte ``address`` (default: all of it)."""
        buf = (ctypes.c_uint8 * size)()
        if self._c.wcsim_flash_read(self._s, address, buf, size) != 0:
            raise ValueError(f"flash {address:#x}+{size} is outside the chip's flash")
        return bytes(buf)

    def save_flash(self) -> Path | None:
        """Writes the flash to ``flash_file`` (when one was given); returns its path."""
        if self.flash_file is None or not self._s:
            return None
        tmp = self.flash_file.with_name(self.flash_file.name + ".tmp")
        tmp.write_bytes(self.read_flash())
        tmp.replace(self.flash_file)
        return self.flash_file

    def close(self) -> None:
        """Saves the flash (``save_flash``), then frees the simulator."""
        if self._s:
            self.save_flash()
        super().close()

    @property
    def pc(self) -> int:
        """The program counter (a byte address)."""
        return int(self._c.wcsim_pc(self._s))

    @property
    def in_bootloader(self) -> bool:
        """True while the core runs in the boot section."""
        return self.pc >= BOOT_START

    # ---- the wire ------------------------------------------------------------------
    def send(self, data: bytes, at: int | None = None) -> list[int]:
        """Hands bytes to the USART, each as soon as its receive FIFO has room (``at``
        is not supported: the wire is flow-controlled, not scheduled)."""
        if at is not None:
            raise ValueError("BootloaderMega feeds bytes as the USART takes them; no 'at'")
        if data:
            buf = (ctypes.c_uint8 * len(data)).from_buffer_copy(data)
            if self._c.wcsim_feed(self._s, buf, len(data)) != 0:
                raise HarnessError("out of memory queueing UART bytes")
        return []

    @property
    def rx_pending(self) -> int:
        """Bytes handed to ``send`` that the USART has not taken yet."""
        return int(self._c.wcsim_feed_pending(self._s))

    def reset(self, cause: str = "external") -> Reset:
        """``VirtualMega.reset``; the bytes not yet taken by the USART are lost."""
        self._c.wcsim_feed_clear(self._s)
        return super().reset(cause)

    def run_until(self, cycle: int) -> None:
        """Runs to ``cycle``, feeding the held bytes to the USART as it takes them."""
        status = self._c.wcsim_run_fed(self._s, int(cycle))
        self._collect()
        if status < 0:
            raise HarnessError(f"the AVR core stopped (crashed) at cycle {self.cycle}, pc {self.pc:#x}")

    def run_to_break(self, cycle: int) -> bool:
        """``run_until``: a chip with no ELF has no hooks to break on; returns False."""
        self.run_until(cycle)
        return False


class BootloaderBoard(MegaBoard):
    """A ``BootloaderMega`` with the chair behind its pins, run by a thread: real time
    while the bootloader runs, then ``speed`` times real time (``realtime=False``:
    flat out). ``reset()`` is DTR."""

    def __init__(self, *, flash_file: str | Path | None = None, program: str | Path | None = None,
                 realtime: bool = True, plant: ChairParams | bool = True, speed: float = 1.0) -> None:
        super().__init__(mega=BootloaderMega(flash_file=flash_file, program=program),
                         realtime=realtime, plant=plant, speed=speed)
        self._anchor: tuple[float, float, float | None] | None = None

    def _rate(self) -> float | None:
        mega = self.mega
        assert isinstance(mega, BootloaderMega)
        if mega.in_bootloader:
            return 1.0
        return self.speed if self.realtime else None

    def _pause(self) -> float:
        rate = self._rate()
        now = time.monotonic()
        if self._anchor is None or self._anchor[2] != rate:
            self._anchor = (self.mega.time, now, rate)
            return 0.0
        sim0, wall0, _ = self._anchor
        if rate is None:
            return 0.0
        return (self.mega.time - sim0) / rate - (now - wall0)
