"""A virtual Arduino Mega 2560: the compiled firmware in simavr, in lock step with Python.

``VirtualMega`` wraps the C harness (``csrc/wcsim.c``, built by ``build``) through ctypes. Time is
simulated cycles at 16 MHz and advances only in ``run_until``/``run_for``; stimulus
is queued at exact cycles, so one trace always gives the same bytes.

    mega = VirtualMega()                  # builds firmware/final_control if needed
    mega.send(b"rp2.0,lp2.0,")            # bytes on the wire from now on
    mega.run_for(0.2)
    print(mega.take_tx_text(), mega.pwm("left"), mega.read("setpointL"))
    mega.reset()                          # DTR: an external reset, the clock running on

A reset (``reset``: external, brown-out, power-on; or the AVR's own watchdog) restarts
the core but not the clock: ``cycle`` keeps counting from the first power-on, queued
bytes and pin edges stay queued at their cycles, the pins driven from outside keep
their levels, and ``resets`` logs each one with MCUSR as the chip shows it.
"""

from __future__ import annotations

import ctypes
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from elftools.elf.elffile import ELFFile
from elftools.elf.sections import SymbolTableSection

from wcdrive.avr.timer0 import F_CPU
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.simavr.build import firmware_elf, harness_library
from wcdrive.errors import WcdriveError
from wcdrive.plant.encoders import EdgeTrain
from wcdrive.protocol.spec import integer

SRAM_OFFSET = 0x800000

#: The Mega 2560's Arduino pin numbers (variants/mega/pins_arduino.h) as (port letter,
#: bit), for the pins the spec assigns.
MEGA_PORT_BIT = {2: ("E", 4), 3: ("E", 5), 7: ("H", 4), 8: ("H", 5), 9: ("H", 6), 10: ("B", 4),
                 11: ("B", 5), 18: ("D", 3), 19: ("D", 2), 22: ("A", 0)}


def _pin(name: str) -> tuple[str, int]:
    return MEGA_PORT_BIT[integer(name)]


# Pins of final_control (protocol/spec.toml, [pins]) as (port letter, bit).
ENCODER_PINS = {"left": (_pin("PIN_ENC_L_A"), _pin("PIN_ENC_L_B")),
                "right": (_pin("PIN_ENC_R_A"), _pin("PIN_ENC_R_B"))}
DIR_PINS = {"left": _pin("PIN_DIR_L"), "right": _pin("PIN_DIR_R")}
RELAY_PIN = _pin("PIN_RELAY")
BRAKE_PIN = _pin("PIN_BRAKE")
# PWM: pin 9 = OC2B on PH6, pin 10 = OC2A on PB4 (Timer2, phase-correct).
_TCCR2A, _OCR2A, _OCR2B = 0xB0, 0xB3, 0xB4
_PWM = {"left": (_OCR2B, 1 << 5, _pin("PIN_PWM_L")), "right": (_OCR2A, 1 << 7, _pin("PIN_PWM_R"))}
_PORT_REG = {"A": 0x22, "B": 0x25, "D": 0x2B, "E": 0x2E, "H": 0x102}
_DDR_REG = {port: address - 1 for port, address in _PORT_REG.items()}

#: C types of the controller globals, for ``read(name)``.
VARIABLE_FORMATS = {
    "f": ("targetL", "targetR", "setpointL", "setpointR", "rawVelL", "rawVelR", "filtVelL",
          "filtVelR", "integralL", "integralR", "prevMeasL", "prevMeasR", "outputL", "outputR",
          "lastTravel", "pendingL", "pendingR", "kpL", "kiL", "kdL", "kpR", "kiR", "kdR",
          "maxWheel", "maxAccel", "estopDecel", "effortSpeedL", "effortSpeedR", "effortSetpointL",
          "effortSetpointR", "overspeedFromL", "overspeedFromR", "haltIntegralL", "haltIntegralR",
          "haltSetpointL", "haltSetpointR"),
    "i": ("encoderValueL", "encoderValueR", "encTickL", "encTickR", "prevEncL", "prevEncR", "holdRefL",
          "holdRefR", "holdStepL", "holdStepR"),
    "I": ("illegalL", "illegalR", "lastControlTime", "tickCount", "lastCmdTime", "rejectedCount",
          "errSuppressed", "txDropped", "timer0_millis", "timer0_overflow_count", "illTickL",
          "illTickR", "rxCount", "crcRejected", "txRingFull", "rxGaps", "rxLost", "rxLostTick",
          "lastTickTime", "lateTicks"),
    "H": ("freeRam", "watchdogMs", "lastSeq", "faultFlags", "txCredit"),
    "B": ("mode", "pwmL", "pwmR", "dirL", "dirR", "pivotPhase", "pivotTicksLeft", "cmdSinceTick",
          "watchdogArmed", "emergencyStop", "ppmLost", "stillTicks", "parked", "cmdLen",
          "cmdCommas", "cmdDiscarding", "errLinesThisTick", "lastEncodedL", "lastEncodedR",
          "timer0_fract", "estopLatched", "tlmEnabled", "linesFramed", "lineCounter", "unframedLine",
          "stormTickL", "stormTickR",
          "stallTicksL", "stallTicksR", "reverseTicksL", "reverseTicksR", "runawayTicksL",
          "runawayTicksR", "stormL", "stormR",
          "resetCause", "effortPwmL", "effortPwmR", "effortTicksL", "effortTicksR", "eeNext", "eeBusy",
          "holding", "holdRollaway", "brakeReleased", "overspeedTicksL", "overspeedTicksR",
          "limitLatched"),
}
_FORMAT_OF = {name: fmt for fmt, names in VARIABLE_FORMATS.items() for name in names}

#: Functions whose entries are logged: (name, what the harness records).
HOOKS = ("processByte", "controlTick", "rxGap", "main", "doneOp", "eepromReady")


#: Reset causes by the harness's code (wcsim.c, ``WCSIM_RESET_*``).
RESET_CAUSES = ("power_on", "external", "brownout", "watchdog")
#: MCUSR's flags (ATmega2560 datasheet, 11.5.1).
PORF, EXTRF, BORF, WDRF, JTRF = 0x01, 0x02, 0x04, 0x08, 0x10


#: Why the USART0 receiver lost a byte (wcsim.c, ``wcsim_rx_lost_t``).
RX_LOSS_CAUSES = ("overrun", "receiver_off")


@dataclass(frozen=True)
class RxLoss:
    """A byte the USART0 receiver lost (the harness models its two-frame FIFO and shift
    register, and data overrun): the cycle, its index among the bytes sent to the board
    (0 the first since power-on), the byte, and why (``RX_LOSS_CAUSES``)."""

    cycle: int
    index: int
    byte: int
    cause: str


class HarnessError(WcdriveError, RuntimeError):
    """The virtual board could not be made or stopped unexpectedly."""


@dataclass(frozen=True)
class Reset:
    """One reset of the AVR: the cycle it happened at, its cause (one of
    ``RESET_CAUSES``) and MCUSR right after it (what the firmware finds at boot)."""

    cycle: int
    cause: str
    mcusr: int


@dataclass(frozen=True)
class Hit:
    """One logged function entry: the cycle, the function, its first 32-bit argument."""

    cycle: int
    function: str
    arg: int


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


def _load_library() -> ctypes.CDLL:
    lib = ctypes.CDLL(str(harness_library()))
    p, u64, u32, i32, sz = ctypes.c_void_p, ctypes.c_uint64, ctypes.c_uint32, ctypes.c_int, ctypes.c_size_t
    u8p = ctypes.POINTER(ctypes.c_uint8)
    sig = {
        "wcsim_new": (p, [ctypes.c_char_p, ctypes.c_char_p, i32]),
        "wcsim_free": (None, [p]),
        "wcsim_cycle": (u64, [p]),
        "wcsim_crashed": (i32, [p]),
        "wcsim_schedule": (i32, [p, u64, i32, i32, i32, i32]),
        "wcsim_schedule_many": (i32, [p, sz, ctypes.POINTER(u64), u8p, u8p, u8p, u8p]),
        "wcsim_add_hook": (i32, [p, u32]),
        "wcsim_set_break_mask": (None, [p, u32]),
        "wcsim_run_until": (i32, [p, u64]),
        "wcsim_tx_count": (sz, [p]),
        "wcsim_tx_take": (sz, [p, ctypes.POINTER(u64), u8p, sz]),
        "wcsim_hits_count": (sz, [p]),
        "wcsim_hits_take": (sz, [p, ctypes.POINTER(u64), ctypes.POINTER(u32), ctypes.POINTER(u32), sz]),
        "wcsim_read": (i32, [p, u32, u8p, u32]),
        "wcsim_write": (i32, [p, u32, u8p, u32]),
        "wcsim_sp": (u32, [p]),
        "wcsim_ramend": (u32, [p]),
        "wcsim_vcd_pwm": (None, [p, i32, i32]),
        "wcsim_vcd_open": (i32, [p, ctypes.c_char_p, ctypes.c_char_p]),
        "wcsim_vcd_close": (None, [p]),
        "wcsim_reset": (i32, [p, i32]),
        "wcsim_mcusr": (ctypes.c_uint8, [p]),
        "wcsim_resets_count": (sz, [p]),
        "wcsim_resets_take": (sz, [p, ctypes.POINTER(u64), u8p, u8p, sz]),
        "wcsim_charge_irq_entry": (None, [p, i32]),
        "wcsim_irq_entries": (u64, [p, i32]),
        "wcsim_prof_set": (i32, [p, i32, ctypes.POINTER(u32), ctypes.POINTER(u32)]),
        "wcsim_prof_get": (u64, [p, i32]),
        "wcsim_pc": (u32, [p]),
        "wcsim_rx_index": (u64, [p]),
        "wcsim_rx_held": (i32, [p]),
        "wcsim_rx_lost_count": (sz, [p]),
        "wcsim_rx_lost_take": (sz, [p, ctypes.POINTER(u64), ctypes.POINTER(u64), u8p, u8p, sz]),
        "wcsim_eeprom_size": (u32, [p]),
        "wcsim_eeprom_read": (i32, [p, u32, u8p, u32]),
        "wcsim_eeprom_write": (i32, [p, u32, u8p, u32]),
    }
    for name, (restype, argtypes) in sig.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


_LIB: ctypes.CDLL | None = None


def _lib() -> ctypes.CDLL:
    global _LIB
    if _LIB is None:
        _LIB = _load_library()
    return _LIB


class VirtualMega:
    """The firmware ELF running in simavr, advanced only by this object's calls."""

    def __init__(self, elf: str | Path | None = None, *, millis_start: int | None = None,
                 vcd: str | Path | None = None, hooks: tuple[str, ...] = (),
                 eeprom: bytes | None = None) -> None:
        """``hooks``: the ELF symbols of further functions whose entries are logged (and
        may be broken on) besides ``HOOKS``, e.g. to time a stretch of code. ``eeprom``:
        the EEPROM's contents from address 0 at power-on (default: erased, 0xFF)."""
        self.elf = Path(elf) if elf is not None else firmware_elf()
        self.variables, self.functions = read_symbols(self.elf)
        missing = [name for name in hooks if name not in self.functions]
        if missing:
            raise HarnessError(f"no function {', '.join(missing)} in {self.elf}")
        self._c = _lib()
        err = ctypes.create_string_buffer(256)
        handle = self._c.wcsim_new(str(self.elf).encode(), err, len(err))
        if not handle:
            raise HarnessError(err.value.decode())
        self._s = handle
        self._hook_names: list[str] = []
        for name in HOOKS + tuple(hooks):
            if name in self.functions and name not in self._hook_names:
                index = self._c.wcsim_add_hook(self._s, self.functions[name])
                if index >= 0:
                    self._hook_names.append(name)
        self._uart_free_at = 0
        self._closed_cycle = 0
        self._pin_level: dict[tuple[str, int], int] = {}
        self.tx_log: list[tuple[int, int]] = []
        #: Whether ``rx_wire`` and ``hit_log`` are kept (the lock-step harness's records);
        #: a live board that runs for hours turns it off, and they stay empty.
        self.keep_records = True
        #: Every byte sent to the board, as (the cycle it reaches the USART, byte), in the
        #: order the receiver gets them (``RxLoss.index`` counts in this list).
        self.rx_wire: list[tuple[int, int]] = []
        #: Every byte the USART0 receiver lost (overrun, or sent while it was off).
        self.rx_lost: list[RxLoss] = []
        self.hit_log: list[Hit] = []
        #: Every reset since power-on, the first power-on (cycle 0) included.
        self.resets: list[Reset] = []
        self._resets_taken = 0
        self._collect_resets()
        # Both encoders rest at count 0, state 11, before the firmware boots.
        for side in ENCODER_PINS:
            for pin in ENCODER_PINS[side]:
                self.set_pin(pin, 1, at=0)
        if vcd is not None:
            pins = "".join(f"{p}{b}:{n};" for n, (p, b) in self._named_pins().items())
            if self._c.wcsim_vcd_open(self._s, str(vcd).encode(), pins.encode()) != 0:
                raise HarnessError(f"cannot open VCD file {vcd}")
            self._vcd = True
        else:
            self._vcd = False
        if eeprom is not None:
            self.write_eeprom(eeprom)
        if millis_start is not None:
            self._start_millis_at(millis_start)

    # ---- lifecycle -----------------------------------------------------------------
    def close(self) -> None:
        """Frees the simulator; ``cycle`` stays readable. Safe to call twice."""
        if self._s:
            self._closed_cycle = self.cycle
            if self._vcd:
                self._c.wcsim_vcd_close(self._s)
            self._c.wcsim_free(self._s)
            self._s = None

    def __enter__(self) -> VirtualMega:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    # ---- time --------------------------------------------------------------------
    @property
    def cycle(self) -> int:
        """Cycles since the first power-on, across resets (after close(), where it
        stopped)."""
        if not self._s:
            return self._closed_cycle
        return int(self._c.wcsim_cycle(self._s))

    @property
    def time(self) -> float:
        """Simulated seconds since the first power-on, across resets."""
        return self.cycle / F_CPU

    @property
    def boot_cycle(self) -> int:
        """The cycle of the last reset (0: none since power-on)."""
        self._collect_resets()
        return self.resets[-1].cycle

    # ---- resets --------------------------------------------------------------------
    def reset(self, cause: str = "external") -> Reset:
        """Resets the AVR now: ``"external"`` (the RESET pin, which DTR pulls on an
        Arduino, or the reset button), ``"brownout"`` or ``"power_on"``. The core
        restarts at its reset vector with every I/O register at its reset value (the
        motor outputs are inputs, unpowered, from the first instruction); SRAM and the
        EEPROM keep their contents (a power-on clears SRAM). MCUSR gets the cause's
        flag (EXTRF, BORF) beside the flags the program has not cleared, or PORF alone
        after a power-on; with WDRF still set the watchdog runs, as on the chip. The
        clock does not restart: ``cycle`` runs on, the queued bytes and edges stay
        queued (bytes that reach the USART before the firmware enables it are lost, as
        on the chip), the pins driven from outside keep their levels. A core that had
        stopped runs again. Returns the reset, also appended to ``resets``."""
        if cause not in ("external", "brownout", "power_on"):
            raise ValueError(f"unknown reset cause {cause!r}: external, brownout or power_on "
                             "(the watchdog resets the board by itself)")
        if self._c.wcsim_reset(self._s, RESET_CAUSES.index(cause)) != 0:
            raise HarnessError(f"the harness refused a {cause} reset")
        self._collect()
        return self.resets[-1]

    @property
    def mcusr(self) -> int:
        """MCUSR now: the reset flags (``PORF``, ``EXTRF``, ``BORF``, ``WDRF``) the
        firmware has not cleared."""
        return int(self._c.wcsim_mcusr(self._s))

    def take_resets(self) -> list[Reset]:
        """The resets since the last call (the first call: the power-on too)."""
        self._collect_resets()
        out = self.resets[self._resets_taken:]
        self._resets_taken = len(self.resets)
        return out

    def run_until(self, cycle: int) -> None:
        """Runs the firmware to ``cycle``, logging every hooked function entry on the way."""
        while self.run_to_break(cycle):
            pass

    def run_to_break(self, cycle: int) -> bool:
        """Runs until ``cycle`` or until a function set with ``break_on`` is entered.
        Returns True when it stopped at such an entry (the last of ``hit_log``)."""
        status = self._c.wcsim_run_until(self._s, int(cycle))
        self._collect()
        if status < 0:
            raise HarnessError(f"the AVR core stopped (crashed) at cycle {self.cycle}")
        return status == 1

    def break_on(self, *functions: str) -> None:
        """Makes ``run_to_break`` stop at the entry of these functions (none: never)."""
        mask = 0
        for name in functions:
            if name not in self._hook_names:
                raise KeyError(f"no hook on {name!r}; hooks: {self._hook_names}")
            mask |= 1 << self._hook_names.index(name)
        self._c.wcsim_set_break_mask(self._s, mask)

    def run_for(self, seconds: float) -> None:
        """Runs the firmware for ``seconds`` of simulated time."""
        self.run_until(self.cycle + round(seconds * F_CPU))

    def _start_millis_at(self, millis: int) -> None:
        """Stops at main() (after .bss is cleared), then sets millis() to ``millis``."""
        if "main" not in self._hook_names:
            raise HarnessError("the ELF has no main symbol to stop at")
        self.break_on("main")
        stopped = self.run_to_break(F_CPU)
        self.break_on()
        if not stopped:
            raise HarnessError("the firmware never reached main()")
        self.write("timer0_millis", millis & 0xFFFFFFFF)

    # ---- stimulus ----------------------------------------------------------------
    def set_pin(self, pin: tuple[str, int], level: int, at: int | None = None) -> None:
        """Drives an input pin (port letter, bit) to ``level`` at cycle ``at`` (default: now)."""
        port, bit = pin
        cycle = self.cycle if at is None else int(at)
        self._c.wcsim_schedule(self._s, cycle, 0, ord(port), bit, 1 if level else 0)
        self._pin_level[pin] = 1 if level else 0

    def send(self, data: bytes, at: int | None = None) -> list[int]:
        """Queues bytes on the RX wire, one per byte time, starting at ``at`` (default:
        now, or when the previous bytes have gone). Returns the cycle each byte starts
        at; it reaches the USART (its stop bit done) one byte time later."""
        start = max(self.cycle if at is None else int(at), self._uart_free_at)
        cycles = [start + i * UART_BYTE_CYCLES for i in range(len(data))]
        for cycle, byte in zip(cycles, data, strict=True):
            self._c.wcsim_schedule(self._s, cycle + UART_BYTE_CYCLES, 1, 0, 0, byte)
            if self.keep_records:
                self.rx_wire.append((cycle + UART_BYTE_CYCLES, byte))
        if data:
            self._uart_free_at = cycles[-1] + UART_BYTE_CYCLES
        return cycles

    def encoder_edges(self, side: str, train: EdgeTrain, t0: float = 0.0) -> None:
        """Queues an encoder's edges; ``train.times`` are seconds after ``t0``."""
        if train.times.size == 0:
            return
        a_pin, b_pin = ENCODER_PINS[side]
        cycles = np.round((t0 + train.times) * F_CPU).astype(np.uint64)
        if np.any(np.diff(cycles.astype(np.int64)) < 0):
            raise ValueError("edge times must not decrease")
        states = train.states.astype(np.int64)
        previous = np.concatenate(([self._state(side)], states[:-1]))
        changed_a = ((previous ^ states) & 0b10) != 0
        changed_b = ((previous ^ states) & 0b01) != 0
        events: list[tuple[int, tuple[str, int], int]] = []
        for cyc, st, ca, cb in zip(cycles.tolist(), states.tolist(), changed_a.tolist(),
                                   changed_b.tolist(), strict=True):
            if ca:
                events.append((cyc, a_pin, (st >> 1) & 1))
            if cb:
                events.append((cyc, b_pin, st & 1))
        self._schedule_pins(events)
        last = int(states[-1])
        self._pin_level[a_pin] = (last >> 1) & 1
        self._pin_level[b_pin] = last & 1

    def _state(self, side: str) -> int:
        a_pin, b_pin = ENCODER_PINS[side]
        return (self._pin_level.get(a_pin, 1) << 1) | self._pin_level.get(b_pin, 1)

    def _schedule_pins(self, events: list[tuple[int, tuple[str, int], int]]) -> None:
        n = len(events)
        if n == 0:
            return
        cycles = (ctypes.c_uint64 * n)(*[e[0] for e in events])
        kinds = (ctypes.c_uint8 * n)()
        ports = (ctypes.c_uint8 * n)(*[ord(e[1][0]) for e in events])
        bits = (ctypes.c_uint8 * n)(*[e[1][1] for e in events])
        values = (ctypes.c_uint8 * n)(*[e[2] for e in events])
        status = self._c.wcsim_schedule_many(self._s, n, cycles, kinds, ports, bits, values)
        if status == -2:
            raise ValueError("pin events must be in cycle order")
        if status != 0:
            raise HarnessError("out of memory queueing pin events")

    # ---- observation -------------------------------------------------------------
    def _collect_resets(self) -> None:
        if not self._s:
            return
        n = self._c.wcsim_resets_count(self._s)
        if n:
            cycles = (ctypes.c_uint64 * n)()
            causes = (ctypes.c_uint8 * n)()
            flags = (ctypes.c_uint8 * n)()
            got = self._c.wcsim_resets_take(self._s, cycles, causes, flags, n)
            self.resets.extend(Reset(cycles[i], RESET_CAUSES[causes[i]], flags[i]) for i in range(got))

    def _collect(self) -> None:
        self._collect_resets()
        n = self._c.wcsim_tx_count(self._s)
        if n:
            cycles = (ctypes.c_uint64 * n)()
            data = (ctypes.c_uint8 * n)()
            got = self._c.wcsim_tx_take(self._s, cycles, data, n)
            self.tx_log.extend(zip(list(cycles[:got]), list(data[:got]), strict=True))
        n = self._c.wcsim_rx_lost_count(self._s)
        if n:
            cycles = (ctypes.c_uint64 * n)()
            indices = (ctypes.c_uint64 * n)()
            data = (ctypes.c_uint8 * n)()
            why = (ctypes.c_uint8 * n)()
            got = self._c.wcsim_rx_lost_take(self._s, cycles, indices, data, why, n)
            self.rx_lost.extend(RxLoss(cycles[i], indices[i], data[i], RX_LOSS_CAUSES[why[i]])
                                for i in range(got))
        n = self._c.wcsim_hits_count(self._s)
        if n:
            cycles = (ctypes.c_uint64 * n)()
            hooks = (ctypes.c_uint32 * n)()
            args = (ctypes.c_uint32 * n)()
            got = self._c.wcsim_hits_take(self._s, cycles, hooks, args, n)
            if self.keep_records:
                self.hit_log.extend(Hit(cycles[i], self._hook_names[hooks[i]], args[i]) for i in range(got))
        if self._vcd:
            self._c.wcsim_vcd_pwm(self._s, self.pwm("left"), self.pwm("right"))

    def take_tx(self) -> list[tuple[int, int]]:
        """TX bytes sent since the last call, each as ``(cycle, byte)``."""
        out, self.tx_log = self.tx_log, []
        return out

    def take_tx_text(self) -> str:
        """The UART bytes sent since the last take, as text."""
        return bytes(b for _, b in self.take_tx()).decode("latin-1")

    def interrupts_taken(self, vector: int) -> int:
        """How many times the interrupt of this vector number was taken since power-on.
        Each costs the chip 5 cycles before its vector (the harness charges them; simavr
        1.6 alone does not)."""
        return int(self._c.wcsim_irq_entries(self._s, vector))

    def profile(self, ranges: list[tuple[int, int]]) -> None:
        """Counts, from now on, the cycles spent with the PC in each ``[lo, hi)`` range
        of flash byte addresses (the first that holds it); ``profiled()`` reads them."""
        n = len(ranges)
        lo = (ctypes.c_uint32 * n)(*[a for a, _ in ranges])
        hi = (ctypes.c_uint32 * n)(*[b for _, b in ranges])
        if self._c.wcsim_prof_set(self._s, n, lo, hi) != 0:
            raise ValueError("at most 16 ranges")
        self._profiled = n

    def profiled(self) -> list[int]:
        """The cycles counted in each range given to ``profile``."""
        return [int(self._c.wcsim_prof_get(self._s, r)) for r in range(getattr(self, "_profiled", 0))]

    @property
    def rx_sent(self) -> int:
        """Bytes that have reached the USART0 receiver since power-on."""
        return int(self._c.wcsim_rx_index(self._s))

    @property
    def rx_held(self) -> int:
        """Bytes the USART0 receiver holds now (its FIFO and shift register, 0 to 3)."""
        return int(self._c.wcsim_rx_held(self._s))

    def take_hits(self) -> list[Hit]:
        """The hooked function entries since the last take."""
        out, self.hit_log = self.hit_log, []
        return out

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

    def pin_output(self, pin: tuple[str, int]) -> int:
        """The level the firmware drives on an output pin (its PORTx bit)."""
        port, bit = pin
        return (self.read_bytes(_PORT_REG[port], 1)[0] >> bit) & 1

    def pwm(self, side: str) -> int:
        """Duty 0..255 on the motor's PWM pin: OCR when the compare output is on,
        else the pin's level (analogWrite 0 and 255 fall back to digitalWrite)."""
        ocr, com_bit, pin = _PWM[side]
        tccr2a = self.read_bytes(_TCCR2A, 1)[0]
        if tccr2a & com_bit:
            return self.read_bytes(ocr, 1)[0]
        return 255 if self.pin_output(pin) else 0

    def direction(self, side: str) -> int:
        """The DIR pin of a motor (1 forward)."""
        return self.pin_output(DIR_PINS[side])

    def relay(self) -> int:
        """The relay pin that powers the motor driver."""
        return self.pin_output(RELAY_PIN)

    def brake_released(self) -> int:
        """1 while the firmware drives the parking brake's pin HIGH as an output (the
        brake released); 0 when it drives it LOW or leaves it an input (at reset: the
        driver's pull-down engages the brake)."""
        port, bit = BRAKE_PIN
        ddr = (self.read_bytes(_DDR_REG[port], 1)[0] >> bit) & 1
        return ddr & self.pin_output(BRAKE_PIN)

    def stack_pointer(self) -> int:
        """The AVR's stack pointer now."""
        return int(self._c.wcsim_sp(self._s))

    def free_ram(self) -> int:
        """Bytes between the end of .bss (no heap is used) and the stack pointer."""
        if "__bss_end" not in self.variables:
            raise HarnessError("the ELF has no __bss_end symbol")
        return self.stack_pointer() - self.variables["__bss_end"][0]

    def _named_pins(self) -> dict[str, tuple[str, int]]:
        return {
            "enc_l_a": ENCODER_PINS["left"][0], "enc_l_b": ENCODER_PINS["left"][1],
            "enc_r_a": ENCODER_PINS["right"][0], "enc_r_b": ENCODER_PINS["right"][1],
            "dir_l": DIR_PINS["left"], "dir_r": DIR_PINS["right"], "relay": RELAY_PIN, "brake": BRAKE_PIN,
            "pwm_l_pin": _PWM["left"][2], "pwm_r_pin": _PWM["right"][2],
        }
