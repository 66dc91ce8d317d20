"""``millis()`` as the Mega counts it (ArduinoCore-avr ``wiring.c``).

Timer0 overflows every 1024 us (16 MHz, prescaler 64, 256 counts). Each overflow
adds 1 ms and 3 to a fraction counter; when the fraction reaches 125 it loses 125
and adds one more ms. So ``millis()`` skips a value about every 42 ms and, over
time, tracks real milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass

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
