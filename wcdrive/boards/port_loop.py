"""The port of the firmware driving the plant at the Mega's own timing, step by step.

Time runs in 16 MHz cycles. ``millis()`` advances at Timer0 overflows (every 16,384
cycles, the first at cycle 21,250 after a reset, as measured on the ELF in simavr). At
each overflow the bytes that have arrived on the wire go through ``processByte``; when
50 ms are due the control tick runs with the plant's encoder counts and its PWM/DIR
drive the plant from then on. The plant steps at a fixed ``dt`` in between.

Faults (``wcdrive.plant.faults``, given as ``faults=``): a healthy encoder's count is
taken from its wheel's angle (``encoder_counts``), the fast path. While an encoder fault
acts on a side (and while the storm guard keeps that encoder masked), that side takes
the edge-level path instead: the wheel's motion over each physics step becomes the
ideal encoder's edges, ``EncoderWire`` makes them what the faulty wire shows, and the
port's interrupt routine (``QuadratureDecoder.edges_in_windows``, with the storm guard's
Timer0 window of each edge) counts them, with its illegal transitions and its storm
guard. When the fault is over the side returns to the fast path, its count going on
from where the fault left it.
Wheel and motor faults act on the plant from the physics step at which they start;
``reset`` faults call ``reset()`` at their cycle.

``PortLoop`` is shared by ``wcdrive sim`` (whole scenarios) and the live simulated
board behind ``wcsim://`` and the pty (small steps paced to the wall clock).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from wcdrive.avr.timer0 import F_CPU, OVERFLOW_CYCLES, TIMER0_START_CYCLE, Timer0, storm_window
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.firmware.eeprom import ReadyInterrupt
from wcdrive.firmware.final_control import Firmware
from wcdrive.firmware.quadrature import QuadratureDecoder
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import edges_from_trajectory, state_for_count
from wcdrive.plant.faults import (
    SIDES,
    EncoderWire,
    Fault,
    apply_plant_faults,
    plant_fault_ticks,
)

__all__ = ["FIRST_OVERFLOW_CYCLE", "F_CPU", "RESET_CAUSE", "SERIAL_READY_CYCLES", "PortLoop", "advance"]

#: The first Timer0 overflow completes at this cycle after reset (measured on the ELF
#: in simavr).
FIRST_OVERFLOW_CYCLE = TIMER0_START_CYCLE + OVERFLOW_CYCLES
#: The BOOT line's cause after ``PortLoop.reset()``: the RESET pin, as DTR pulls it.
RESET_CAUSE = "EXTERNAL"
#: Cycles from a reset until ``setup()``'s ``Serial.begin`` enables the receiver
#: (measured on the ELF in simavr): bytes that arrive earlier are lost.
SERIAL_READY_CYCLES = 10_723


class _Encoder:
    """One encoder as the port sees it: the fast path (``offset`` added to the count the
    wheel's angle gives) or the edge path (``decoder`` over ``wire``'s edges)."""

    def __init__(self, side: str, wire: EncoderWire | None) -> None:
        self.side = side
        self.sign = -1.0 if side == "left" else 1.0      # the left encoder counts down forward
        self.wire = wire
        self.offset = 0
        self.decoder = QuadratureDecoder()
        self.edge_mode = False

    def count(self, true_count: int) -> int:
        """The count the ISR holds when the wheel's ideal count is ``true_count``."""
        return self.decoder.count if self.edge_mode else true_count + self.offset

    def needs_edges(self, lo: int, hi: int) -> bool:
        """Whether the span (lo, hi] of cycles takes the edge path."""
        return self.edge_mode or (self.wire is not None and self.wire.active(lo, hi))

    def enter(self, true_count: int) -> None:
        """To the edge path: the decoder holds what the fast path gave so far."""
        state = int(state_for_count(true_count))
        assert self.wire is not None
        self.wire.resync(state)
        self.decoder.count = true_count + self.offset
        self.decoder.last = state
        self.edge_mode = True

    def leave_if_healthy(self, true_count: int, cycle: int) -> None:
        """Back to the fast path once no fault acts and the encoder is not masked."""
        if self.edge_mode and not self.decoder.storm and (
                self.wire is None or not self.wire.faulted_at(cycle)):
            self.offset = self.decoder.count - true_count
            self.edge_mode = False

    def pin_state(self, true_count: int) -> int:
        """The AB state on the board's pins now."""
        if self.edge_mode and self.wire is not None:
            return self.wire.state
        return int(state_for_count(true_count))

    def reboot(self, true_count: int) -> None:
        """The board reset: the ISR's globals start again from 0 (setup() reads the pins)."""
        self.decoder = QuadratureDecoder(last=self.pin_state(true_count))
        self.offset = -true_count
        if self.edge_mode:
            self.decoder.count = 0


class PortLoop:
    """The port driving the plant, run in 16 MHz cycles (module docstring); ``faults``
    are injected as the module docstring says."""

    def __init__(self, plant: Plant, gyro: Gyro | None = None, dt: float = 0.001,
                 firmware: Firmware | None = None, faults: Sequence[Fault] = ()) -> None:
        self.plant = plant
        self.gyro = gyro
        self.dt = dt
        self.step_cycles = round(dt * F_CPU)
        self.fw = firmware or Firmware(boot_millis=0)
        self.timer = Timer0()
        self.cycle = 0                   # simulated time reached
        self.boot_cycle = 0              # the last reset
        #: The cycle of the last control tick (None: none yet).
        self.last_tick_cycle: int | None = None
        self._overflow = FIRST_OVERFLOW_CYCLE
        self._eeprom_ready = ReadyInterrupt()
        self._steps_done = 0
        self._rx: deque[tuple[int, int]] = deque()
        self._wire_free = 0
        self.output: list[tuple[int, bytes]] = [(0, self.fw.boot_output())]
        self.faults = tuple(faults)
        self._scale = plant.p.counts_per_rev / (2.0 * math.pi)
        self._encoders = {side: _Encoder(side, self._wire(side)) for side in SIDES}
        self._plant_steps = sorted({-(-c // self.step_cycles) for c in plant_fault_ticks(self.faults, F_CPU)})
        self._resets = sorted(f.cycles(F_CPU)[0] for f in self.faults if f.kind == "reset")

    def _wire(self, side: str) -> EncoderWire | None:
        wire = EncoderWire(self.faults, side, F_CPU)
        return wire if wire.faulty else None

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
        plant = self.plant
        while True:
            overflow = self._overflow
            if self._resets and self._resets[0] <= min(overflow, end_cycle):
                cycle = self._resets.pop(0)
                self._advance_to(cycle)
                self.cycle = max(self.cycle, cycle)
                self.reset()
                continue
            if overflow > end_cycle:
                break
            fw = self.fw
            self.timer.overflow()
            if self._rx and self._rx[0][0] <= overflow:
                data = bytearray()
                while self._rx and self._rx[0][0] <= overflow:
                    data.append(self._rx.popleft()[1])
                masked = any(e.decoder.storm for e in self._encoders.values())
                if masked:
                    self._advance_to(overflow)
                out = fw.feed(bytes(data))
                if out:
                    self.output.append((overflow, out))
                if masked:
                    self._unmask_cleared(overflow)
            self._eeprom_ready.poll(fw.state, overflow)
            millis = self.timer.millis
            if fw.due(millis):
                self._advance_to(overflow)
                true = self._true_counts()
                left, right = self._encoders["left"], self._encoders["right"]
                out = fw.tick(millis, left.count(true[0]), right.count(true[1]),
                              left.decoder.illegal, right.decoder.illegal,
                              storm_l=int(left.decoder.storm), storm_r=int(right.decoder.storm))
                s = fw.state
                plant.set_drive(s.pwmL, s.dirL, s.pwmR, s.dirR)
                self.output.append((overflow, out))
                self.last_tick_cycle = overflow
                if on_tick:
                    on_tick(overflow / F_CPU)
            self._overflow += OVERFLOW_CYCLES
        self._advance_to(end_cycle)
        self.cycle = max(self.cycle, end_cycle)

    def reset(self) -> None:
        """The board resets now (``cycle``), as the RESET pin (DTR) does: a fresh
        ``setup()`` whose Timer0 starts as after a power-on (the first overflow
        ``FIRST_OVERFLOW_CYCLE`` cycles later), the motors unpowered at once, the ISRs'
        counts from 0, and the BOOT line with the cause ``RESET_CAUSE``. Bytes that
        arrive before the new ``setup()`` enables the receiver (``SERIAL_READY_CYCLES``)
        are lost; later ones reach the new firmware."""
        now = self.cycle
        self._advance_to(now)
        # The EEPROM survives, as far as a save had written it.
        self.fw = Firmware(boot_millis=0, eeprom=self.fw.state.eeprom, cause=RESET_CAUSE)
        self._eeprom_ready = ReadyInterrupt()
        self.timer = Timer0()
        self.boot_cycle = now
        self._overflow = now + FIRST_OVERFLOW_CYCLE
        while self._rx and self._rx[0][0] < now + SERIAL_READY_CYCLES:
            self._rx.popleft()
        true = self._true_counts()
        for enc, count in zip(self._encoders.values(), true, strict=True):
            enc.reboot(count)
        s = self.fw.state
        self.plant.set_drive(s.pwmL, s.dirL, s.pwmR, s.dirR)
        self.output.append((now, self.fw.boot_output()))

    def encoder_counts(self) -> tuple[int, int]:
        """The counts the ISRs hold at the plant's present step (left, right)."""
        true = self._true_counts()
        return self._encoders["left"].count(true[0]), self._encoders["right"].count(true[1])

    def encoder_states(self) -> tuple[int, int]:
        """The AB states on the encoder pins at the plant's present step (left, right)."""
        true = self._true_counts()
        return (self._encoders["left"].pin_state(true[0]), self._encoders["right"].pin_state(true[1]))

    def _true_counts(self) -> tuple[int, int]:
        """What ideal encoders count for the wheels' angles now (``encoder_counts``)."""
        p = self.plant
        return math.floor(-p.left.angle * self._scale), math.floor(p.right.angle * self._scale)

    def _unmask_cleared(self, cycle: int) -> None:
        """After ``reset`` cleared a storm flag: that ISR on again, the pins read afresh."""
        s = self.fw.state
        true = self._true_counts()
        pairs = ((self._encoders["left"], "stormL"), (self._encoders["right"], "stormR"))
        for (enc, flag), count in zip(pairs, true, strict=True):
            if enc.decoder.storm and not getattr(s, flag, 1):
                enc.decoder.unmask(enc.pin_state(count))
                enc.leave_if_healthy(count, cycle)

    def _advance_to(self, cycle: int) -> None:
        target = cycle // self.step_cycles
        while self._steps_done < target:
            stop = target
            for step in self._plant_steps:
                if self._steps_done < step < stop:
                    stop = step
                    break
            self._advance_steps(stop - self._steps_done)
            if self._plant_steps:
                apply_plant_faults(self.plant, self.faults, self._steps_done * self.step_cycles, F_CPU)

    def _advance_steps(self, n: int) -> None:
        lo = self._steps_done * self.step_cycles
        hi = (self._steps_done + n) * self.step_cycles
        edge_sides = [enc for enc in self._encoders.values() if enc.needs_edges(lo, hi)]
        previous = (self.plant.left.angle, self.plant.right.angle)
        angles = advance(self.plant, self.gyro, n, self.dt)
        assert angles is not None
        self._steps_done += n
        for enc in edge_sides:
            i = 0 if enc.side == "left" else 1
            positions = enc.sign * np.concatenate(([previous[i]], angles[:, i])) * self._scale
            if not enc.edge_mode:
                enc.enter(math.floor(positions[0]))
            times = lo + self.step_cycles * np.arange(n + 1, dtype=np.float64)
            train = edges_from_trajectory(times, positions)
            ticks = np.clip(np.round(train.times).astype(np.int64), lo + 1, hi)
            states = train.states
            if enc.wire is not None:
                ticks, states = enc.wire.transform(lo, hi, ticks, states)
            if ticks.size and not enc.decoder.storm:
                enc.decoder.edges_in_windows(states, storm_window(ticks - self.boot_cycle))
                if enc.decoder.storm:
                    setattr(self.fw.state, "stormL" if enc.side == "left" else "stormR", 1)
            enc.leave_if_healthy(math.floor(positions[-1]), hi)


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
