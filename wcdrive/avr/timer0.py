"""``millis()`` as the Mega counts it (ArduinoCore-avr ``wiring.c``).

Timer0 overflows every 1024 us (16 MHz, prescaler 64, 256 counts). Each overflow
adds 1 ms and 3 to a fraction counter; when the fraction reaches 125 it loses 125
and adds one more ms. So ``millis()`` skips a value about every 42 ms and, over
time, tracks real milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import overload

import numpy as np

F_CPU = 16_000_000
OVERFLOW_CYCLES = 64 * 256
OVERFLOW_US = 1024
MILLIS_INC = OVERFLOW_US // 1000
FRACT_INC = (OVERFLOW_US % 1000) >> 3
FRACT_MAX = 1000 >> 3


@dataclass
class Timer0:
    """The overflow interrupt's state: ``timer0_millis`` and ``timer0_fract``."""

    millis: int = 0
    fract: int = 0

    def overflow(self) -> None:
        """One ``TIMER0_OVF_vect``: ``millis`` up by 1, and 1 more when ``fract`` reaches 125."""
        m = self.millis + MILLIS_INC
        f = self.fract + FRACT_INC
        if f >= FRACT_MAX:
            f -= FRACT_MAX
            m += 1
        self.millis = m & 0xFFFFFFFF
        self.fract = f


def millis_after(overflows: int, start_millis: int = 0, start_fract: int = 0) -> int:
    """``millis()`` after ``overflows`` Timer0 overflows from the given state."""
    total_fract = start_fract + FRACT_INC * overflows
    return (start_millis + MILLIS_INC * overflows + total_fract // FRACT_MAX) & 0xFFFFFFFF


def overflows_until(target_elapsed: int, start_fract: int = 0) -> int:
    """The fewest overflows after which ``millis()`` has advanced by at least
    ``target_elapsed`` ms from a state with fraction ``start_fract``."""
    n = max(0, (target_elapsed * FRACT_MAX) // (FRACT_MAX + FRACT_INC) - 2)
    while millis_after(n, 0, start_fract) < target_elapsed:
        n += 1
    return n


#: The cycle at which Timer0 starts counting after reset (``init()`` in wiring.c sets its
#: prescaler): its first overflow interrupt is done 16,384 cycles later, at cycle 30,989,
#: as measured on the ELF in simavr (tests/firmware/test_fault_mutants.py checks it; it moves
#: when the start-up code before ``init()`` grows: 21,250 for firmware 3.0.0, 24,955
#: before the sketch had its own serial class, whose constructor and larger .bss run
#: first; the harness now also charges the 5 cycles of each interrupt entry; 25,987 with
#: the EEPROM parameters' .bss and .data; then the 26 bytes of v4's line buffer and
#: counter, in .data since the buffer is a member of an object with a vtable: 6 cycles a
#: byte of the start-up copy), 26,142; then the integrals and setpoints an emergency ramp
#: keeps; 26,497 with the neutral rule's; then the inhibit inputs' globals and their
#: pin set-up, 26,557; the brake's and push mode's globals took it to 26,746 unseen, within
#: the test's 200; then the windings' estimates, in .data, and the 8 bytes more of the
#: line buffer, 26,950; then the supply sense's set-up in ``setup()`` and its globals,
#: 26,994; then the drive limits' seven globals and their parameter table's entries, in
#: .data, 28,171; then the drive profiles, whose table and the larger EEPROM block went to
#: .noinit, which is not cleared, taking the block's 71 bytes out of .bss, 27,751; then the
#: motors' current counts, in .data at 0 A's count, 27,773; then stall_timeout and its
#: parameter table's entries, in .data, 27,917; then the TX ring's 512 bytes more, in
#: .bss, whose clearing takes 6 cycles a byte, 30,989; then 14 bytes more of .data, which
#: the link-time optimiser moved there when the stall rule's spin test came in, 31,115;
#: then tremor_damping and the damped goals, 12 bytes of .bss, 31,190).
TIMER0_START_CYCLE = 31_190 - OVERFLOW_CYCLES


_WINDOW_START = TIMER0_START_CYCLE + 128 * 64


@overload
def storm_window(cycle: int) -> int: ...
@overload
def storm_window(cycle: np.ndarray) -> np.ndarray: ...
def storm_window(cycle: int | np.ndarray) -> int | np.ndarray:
    """The Timer0 period an instant (cycles since reset; an int or an array) falls in,
    for the encoders' storm guard: windows start when Timer0's count passes
    ``STORM_COMPARE`` (128, the TIMER0_COMPA interrupt that clears the ISRs' edge
    counts), one per 16,384 cycles."""
    if isinstance(cycle, np.ndarray):
        return (cycle.astype(np.int64) - _WINDOW_START) // OVERFLOW_CYCLES
    return (cycle - _WINDOW_START) // OVERFLOW_CYCLES


def micros_at(cycle: int) -> int:
    """What ``micros()`` returns at ``cycle`` (cycles since reset): Timer0's total count
    (overflows * 256 + TCNT0, one count per 64 cycles) times 4 us, modulo 2**32."""
    return (max(0, cycle - TIMER0_START_CYCLE) // 64 * 4) & 0xFFFFFFFF
