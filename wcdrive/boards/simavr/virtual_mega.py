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
their levels (the analog inputs too), and ``resets`` logs each one with MCUSR as the
chip shows it.

The analog inputs (``set_analog``) take millivolts, AVcc 5 V the reference; the supply
sense (A0, ``wcdrive.boards.supply_sense``) starts at a 24 V battery's ``NOMINAL_MV``.

This module holds ``VirtualMega``: its life, its clock and resets, the stimulus it
queues and the records it gathers. The rest is where its concerns part, and
importable from here too: the ctypes binding to the harness (``_lib``,
``HarnessError``) in ``harness_binding``; the records (``Reset``, ``Hit``,
``RxLoss``, the reset causes and MCUSR flags) in ``harness_records``; the memory by
the firmware's names (``read_symbols``, ``VARIABLE_FORMATS``, ``MegaMemory``) in
``mega_memory``; the pin map and the outputs (``ENCODER_PINS``, ``MegaPins``) in
``mega_pins``.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from wcdrive.avr.timer0 import F_CPU
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.current_sense import CURRENT_CHANNELS
from wcdrive.boards.current_sense import ZERO_MV as CURRENT_ZERO_MV
from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.boards.simavr.harness_binding import HarnessError, _lib
from wcdrive.boards.simavr.harness_records import (
    BORF,
    EXTRF,
    JTRF,
    PORF,
    RESET_CAUSES,
    RX_LOSS_CAUSES,
    WDRF,
    Hit,
    Reset,
    RxLoss,
)
from wcdrive.boards.simavr.mega_memory import SRAM_OFFSET, VARIABLE_FORMATS, read_symbols
from wcdrive.boards.simavr.mega_pins import (
    BRAKE_PIN,
    DIR_PINS,
    ENCODER_PINS,
    INPUT_PINS,
    MEGA_PORT_BIT,
    RELAY_PIN,
    MegaPins,
)
from wcdrive.boards.supply_sense import NOMINAL_MV, SUPPLY_CHANNEL
from wcdrive.plant.encoders import EdgeTrain

__all__ = ["ANALOG_CHANNELS", "BORF", "BRAKE_PIN", "DIR_PINS", "ENCODER_PINS", "EXTRF", "F_CPU", "HOOKS",
           "JTRF", "MEGA_PORT_BIT", "PORF", "RELAY_PIN", "RESET_CAUSES", "RX_LOSS_CAUSES", "SRAM_OFFSET",
           "VARIABLE_FORMATS", "WDRF", "HarnessError", "Hit", "Reset", "RxLoss", "VirtualMega",
           "read_symbols"]

#: Functions whose entries are logged: (name, what the harness records).
HOOKS = ("processByte", "controlTick", "rxGap", "main", "doneOp", "eepromReady")
#: The analog channels the harness drives (simavr 1.6 keeps a value for ADC0..ADC7), and
#: the event kind that sets one (``csrc/wcsim.c``).
ANALOG_CHANNELS = range(8)
_ANALOG_EVENT = 2


class VirtualMega(MegaPins):
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
        self._analog: dict[int, int] = {}
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
        # Both encoders rest at count 0, state 11, before the firmware boots; the
        # inhibit inputs read HIGH (released), as their pull-ups hold an unwired pin.
        for side in ENCODER_PINS:
            for pin in ENCODER_PINS[side]:
                self.set_pin(pin, 1, at=0)
        for pin in INPUT_PINS.values():
            self.set_pin(pin, 1, at=0)
        # The supply sense reads a 24 V battery until someone (a plant) says otherwise.
        self.set_analog(SUPPLY_CHANNEL, NOMINAL_MV, at=0)
        # ...and the motors' current senses read 0 A (wcdrive.boards.current_sense).
        for channel in CURRENT_CHANNELS.values():
            self.set_analog(channel, CURRENT_ZERO_MV, at=0)
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
    def pin_level(self, pin: tuple[str, int]) -> int:
        """The level last driven on an input pin (``set_pin``; 1 for one never driven)."""
        return self._pin_level.get(pin, 1)

    def set_pin(self, pin: tuple[str, int], level: int, at: int | None = None) -> None:
        """Drives an input pin (port letter, bit) to ``level`` at cycle ``at`` (default: now)."""
        port, bit = pin
        cycle = self.cycle if at is None else int(at)
        self._c.wcsim_schedule(self._s, cycle, 0, ord(port), bit, 1 if level else 0)
        self._pin_level[pin] = 1 if level else 0

    def analog(self, channel: int) -> int:
        """The millivolts last set on an analog input (``set_analog``; 0 for one never
        set), whether or not their cycle has come."""
        return self._analog.get(channel, 0)

    def set_analog(self, channel: int, millivolts: int, at: int | None = None) -> None:
        """Puts ``millivolts`` (0..65535) on analog input ``channel`` (ADC0..ADC7, A0..A7)
        from cycle ``at`` (default: now) on. The ADC converts the value on the pin when
        the firmware reads ADCL (simavr samples lazily), scaled by AVcc, 5 V
        (``wcdrive.boards.supply_sense.adc_counts``); resets keep it."""
        if channel not in ANALOG_CHANNELS:
            raise ValueError(f"no analog input {channel}: 0 to 7")
        mv = int(millivolts)
        if not 0 <= mv <= 0xFFFF:
            raise ValueError(f"{millivolts} mV is outside 0..65535")
        cycle = self.cycle if at is None else int(at)
        if self._c.wcsim_schedule(self._s, cycle, _ANALOG_EVENT, 0, channel, mv) != 0:
            raise HarnessError("out of memory queueing an analog input")
        self._analog[channel] = mv

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
