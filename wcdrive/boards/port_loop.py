"""The port of the firmware driving the plant at the Mega's own timing, step by step.

Time runs in 16 MHz cycles. ``millis()`` advances at Timer0 overflows (every 16,384
cycles, the first at cycle 21,250 as measured on the ELF in simavr). At each overflow
the bytes that have arrived on the wire go through ``processByte``; when 50 ms are due
the control tick runs with the plant's encoder counts and its PWM/DIR drive the plant
from then on. The plant steps at a fixed ``dt`` in between.

``PortLoop`` is shared by ``wcdrive sim`` (whole scenarios) and the live simulated
board behind ``wcsim://`` and the pty (small steps paced to the wall clock).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np

from wcdrive.avr.timer0 import F_CPU, OVERFLOW_CYCLES, Timer0
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.firmware.final_control import Firmware
from wcdrive.plant import Gyro, Plant, encoder_counts

__all__ = ["FIRST_OVERFLOW_CYCLE", "F_CPU", "PortLoop", "advance"]

#: The first Timer0 overflow completes at this cycle after reset (measured on the ELF
#: in simavr).
FIRST_OVERFLOW_CYCLE = 21_250


class PortLoop:
    """The port driving the plant, run in 16 MHz cycles (module docstring)."""

    def __init__(self, plant: Plant, gyro: Gyro | None = None, dt: float = 0.001,
                 firmware: Firmware | None = None) -> None:
        self.plant = plant
        self.gyro = gyro
        self.dt = dt
        self.step_cycles = round(dt * F_CPU)
        self.fw = firmware or Firmware(boot_millis=0)
        self.timer = Timer0()
        self.cycle = 0                   # simulated time reached
        self._overflow = FIRST_OVERFLOW_CYCLE
        self._steps_done = 0
        self._rx: deque[tuple[int, int]] = deque()
        self._wire_free = 0
        self.output: list[tuple[int, bytes]] = [(0, self.fw.boot_output())]

    def send(self, data: bytes, at: int | None = None) -> None:
        """Bytes onto the RX wire from cycle ``at`` (default: now), one per byte time."""
        start = max(self.cycle if at is None else at, self._wire_free)
        for i, b in enumerate(data):
            self._rx.append((start + (i + 1) * UART_BYTE_CYCLES, b))
        self._wire_free = start + len(data) * UART_BYTE_CYCLES

    def take_output(self) -> list[tuple[int, bytes]]:
        """What the firmware sent since the last take, as (cycle, bytes)."""
        out, self.output = self.output, []
        return out

    def run_until(self, end_cycle: int, on_tick: Callable[[float], None] | None = None) -> None:
        """Runs to ``end_cycle``; ``on_tick(time)`` after every control tick."""
        fw, plant = self.fw, self.plant
        while self._overflow <= end_cycle:
            overflow = self._overflow
            self.timer.overflow()
            if self._rx and self._rx[0][0] <= overflow:
                data = bytearray()
                while self._rx and self._rx[0][0] <= overflow:
                    data.append(self._rx.popleft()[1])
                out = fw.feed(bytes(data))
                if out:
                    self.output.append((overflow, out))
            millis = self.timer.millis
            if fw.due(millis):
                self._advance_to(overflow)
                counts = encoder_counts(plant.left.angle, plant.right.angle, plant.p.counts_per_rev)
                out = fw.tick(millis, *counts)
                s = fw.state
                plant.set_drive(s.pwmL, s.dirL, s.pwmR, s.dirR)
                self.output.append((overflow, out))
                if on_tick:
                    on_tick(overflow / F_CPU)
            self._overflow += OVERFLOW_CYCLES
        self._advance_to(end_cycle)
        self.cycle = max(self.cycle, end_cycle)

    def _advance_to(self, cycle: int) -> None:
        target = cycle // self.step_cycles
        advance(self.plant, self.gyro, target - self._steps_done, self.dt)
        self._steps_done = max(self._steps_done, target)


def advance(plant: Plant, gyro: Gyro | None, steps: int, dt: float) -> np.ndarray | None:
    """``steps`` plant steps; the gyro samples the yaw rate of the step it falls in.
    Returns the wheel angles after each step (or None for no steps)."""
    if steps <= 0:
        return None
    t0 = plant.time
    recorded = plant.advance(steps, dt, record=True)
    assert recorded is not None
    angles, rates = recorded
    if gyro is not None:
        end = t0 + dt * steps
        while gyro.next_time <= end + 1e-12:
            k = min(steps - 1, max(0, int((gyro.next_time - t0) / dt - 1e-9)))
            gyro.sample(gyro.next_time, float(rates[k]))
    return angles
