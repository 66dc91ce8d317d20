"""The port of the firmware driving the plant at the Mega's own timing.

Time runs in 16 MHz cycles. ``millis()`` advances at Timer0 overflows (every 16,384
cycles, the first at ``FIRST_OVERFLOW_CYCLE`` after a reset, as measured on the ELF in
simavr). At each overflow the bytes that have arrived on the wire go through
``processByte``; when ``Firmware.due`` says so the control tick runs with the plant's
encoder counts and its PWM/DIR drive the plant from then on. The plant steps at a fixed
``dt`` in between, a tick's steps in one call of its C kernel (``Plant.advance_batch``),
the gyro's samples of those steps in one more (``Gyro.sample_steps``).

``run_until`` is event-driven: nothing happens at an overflow unless bytes
are read or the tick runs there, so it jumps from event to event: the overflow at which
the next bytes have arrived or a ``save``'s EEPROM-ready interrupt is due, the first
overflow at which ``Firmware.due`` holds (from ``Firmware.due_after``, the same
condition solved for the time), a reset, the end.
``millis()`` there comes in closed form from Timer0's model (``millis_after``: 1 ms and
3/125 of one per overflow). The firmware alone decides when it ticks (``due`` and
``due_after`` side by side), so a change of its timing needs no change here.
``stepped=True`` runs the reference path, every overflow in turn with ``due`` asked at
each; tests/sim/test_sim_speed.py holds the two to the same bytes, ticks and states.

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

The supply sense: each tick reads the ADC count of the battery's terminal voltage as
the plant last computed it (``Plant.battery``), through the divider as the compiled
firmware's board reads it (``wcdrive.boards.supply_sense``); ``set_supply`` puts a
voltage of the caller's in its place. The motors' current senses: each tick reads the
counts of the plant's motor currents as they were just after the last tick began (the
ADC interrupt's conversions, ``wcdrive.boards.current_sense``).

``PortLoop`` is shared by ``wcdrive sim`` (whole scenarios) and the live simulated
board behind ``wcsim://`` and the pty (small steps paced to the wall clock).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from wcdrive.avr.timer0 import (
    F_CPU,
    FRACT_INC,
    FRACT_MAX,
    MILLIS_INC,
    OVERFLOW_CYCLES,
    TIMER0_START_CYCLE,
    Timer0,
    storm_window,
)
from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.current_sense import plant_current_millivolts
from wcdrive.boards.inhibits import LEVER_INPUT, InhibitChange, input_number
from wcdrive.boards.supply_sense import SupplyOverrides, adc_counts, pin_millivolts, plant_millivolts
from wcdrive.firmware import constants as C
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
SERIAL_READY_CYCLES = 10_987


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


class _Wire:
    """The bytes on their way to the board's RX pin, as runs ``[start, data, taken]``:
    byte ``i`` of a run has fully arrived at ``start + (i + 1) * UART_BYTE_CYCLES``."""

    def __init__(self) -> None:
        self._runs: deque[list] = deque()

    def __bool__(self) -> bool:
        return bool(self._runs)

    def push(self, start: int, data: bytes) -> None:
        """``data`` sent from cycle ``start`` on, after any bytes already on the wire."""
        self._runs.append([start, data, 0])

    def next_arrival(self) -> int:
        """The cycle at which the next byte has arrived (the wire is not empty)."""
        start, _, taken = self._runs[0]
        return start + (taken + 1) * UART_BYTE_CYCLES

    def take(self, cycle: int) -> bytes:
        """The bytes that have arrived by ``cycle``, off the wire."""
        out = b""
        runs = self._runs
        while runs:
            run = runs[0]
            start, data, taken = run
            arrived = min(len(data), (cycle - start) // UART_BYTE_CYCLES)
            if arrived <= taken:
                break
            out += data[taken:arrived]
            if arrived < len(data):
                run[2] = arrived
                break
            runs.popleft()
        return out

    def drop_before(self, cycle: int) -> None:
        """Loses the bytes that arrive before ``cycle``."""
        self.take(cycle - 1)


class PortLoop:
    """The port driving the plant, run in 16 MHz cycles (module docstring); ``faults``
    are injected as the module docstring says."""

    def __init__(self, plant: Plant, gyro: Gyro | None = None, dt: float = 0.001,
                 firmware: Firmware | None = None, faults: Sequence[Fault] = (), *,
                 stepped: bool = False, inhibits: Sequence[InhibitChange] = ()) -> None:
        self.plant = plant
        #: The reference path: every Timer0 overflow in turn (``run_until``).
        self.stepped = stepped
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
        self._rx = _Wire()
        self._wire_free = 0
        self.output: list[tuple[int, bytes]] = [(0, self.fw.boot_output())]
        self.faults = tuple(faults)
        #: The inhibit inputs active now (bit 0 input 1, bit 1 input 2), and their
        #: changes still to come, by time (``set_inhibit`` adds to them); a change of
        #: input 4, the brake's manual release, moves the plant's lever, which the board
        #: reads (``Plant.brake_lever``).
        self.inhibit_bits = 0
        self._inhibits_due = sorted(inhibits, key=lambda c: c.at)
        self._supply = SupplyOverrides()
        #: The motors' current counts the next tick reads: what the ADC interrupt
        #: converted after the last tick began (the firmware's globals start at
        #: CURRENT_ZERO_COUNTS until the first tick's conversions).
        self._currents = (C.CURRENT_ZERO_COUNTS, C.CURRENT_ZERO_COUNTS)
        self._scale = plant.p.counts_per_rev / (2.0 * math.pi)
        self._encoders = {side: _Encoder(side, self._wire(side)) for side in SIDES}
        self._left, self._right = self._encoders["left"], self._encoders["right"]
        self._plant_steps = sorted({-(-c // self.step_cycles) for c in plant_fault_ticks(self.faults, F_CPU)})
        self._resets = sorted(f.cycles(F_CPU)[0] for f in self.faults if f.kind == "reset")

    def _wire(self, side: str) -> EncoderWire | None:
        wire = EncoderWire(self.faults, side, F_CPU)
        return wire if wire.faulty else None

    def send(self, data: bytes, at: int | None = None) -> None:
        """Bytes onto the RX wire from cycle ``at`` (default: now), one per byte time."""
        start = max(self.cycle if at is None else at, self._wire_free)
        if data:
            self._rx.push(start, bytes(data))
        self._wire_free = start + len(data) * UART_BYTE_CYCLES

    def set_inhibit(self, number: int, active: bool, at: int | None = None) -> None:
        """Inhibit input ``number`` (1 the charger, 2 the seat; 4 the brake's manual
        release, pulled on the plant) active (its pin LOW) or released from cycle ``at``
        (default: now) on."""
        when = self.cycle if at is None else at
        bisect.insort(self._inhibits_due, InhibitChange(when / F_CPU, input_number(number), active),
                      key=lambda c: c.at)

    def set_supply(self, volts: float | None, at: int | None = None) -> None:
        """The battery reads ``volts`` at the supply sense from cycle ``at`` (default:
        now) on, in place of the plant's terminal voltage; None gives it back to the
        plant."""
        self._supply.set(self.cycle if at is None else at, volts)

    def supply_counts(self, cycle: int) -> int:
        """The ADC count the tick reads at ``cycle``: the supply ``set_supply`` set for
        then, else the plant's terminal voltage now, as the compiled firmware's board
        reads it (``adc_counts(pin_millivolts(volts))``). Asked in non-decreasing cycles."""
        volts = self._supply.at(cycle)
        return adc_counts(plant_millivolts(self.plant) if volts is None else pin_millivolts(volts))

    def take_output(self) -> list[tuple[int, bytes]]:
        """What the firmware sent since the last take, as (cycle, bytes)."""
        out, self.output = self.output, []
        return out

    def run_until(self, end_cycle: int, on_tick: Callable[[float], None] | None = None) -> None:
        """Runs to ``end_cycle``; ``on_tick(time)`` after every control tick.

        Event-driven (module docstring): from one event to the next (a control tick, the
        overflow at which received bytes are read or an EEPROM write's ready interrupt is
        due, a reset, the end), ``millis()`` in closed form. ``stepped=True`` takes the
        reference path, every overflow in turn."""
        if self.stepped:
            self._run_stepped(end_cycle, on_tick)
            return
        while True:
            overflow = self._overflow
            resets = self._resets
            if self._reset_due(end_cycle):
                continue
            if overflow > end_cycle:
                break
            # The last overflow this pass may reach: none past the end, none at or past
            # a reset, and the bytes' overflow (read before its due check) at most.
            last = overflow + (end_cycle - overflow) // OVERFLOW_CYCLES * OVERFLOW_CYCLES
            if resets:
                last = min(last, overflow + (resets[0] - 1 - overflow) // OVERFLOW_CYCLES * OVERFLOW_CYCLES)
            # The overflow at which loop() has something to do besides the tick: bytes
            # that have arrived (read before its due check), or an EEPROM-ready interrupt
            # of a save in progress (polled at every overflow on the stepped path).
            io_at: int | None = None
            arrived = self._rx.next_arrival() if self._rx else None
            if arrived is not None:
                io_at = _overflow_at(arrived, overflow)
            writing = self.fw.state.eeBusy
            if writing:
                ready = self._eeprom_ready.due
                ee_at = overflow if ready is None else _overflow_at(ready, overflow)
                io_at = ee_at if io_at is None else min(io_at, ee_at)
            if io_at is not None and io_at > last:
                io_at = None
            if not writing and self._eeprom_ready.due is not None and (io_at is None or io_at > overflow):
                # No save in progress (a firmware put in mid-save), and no byte read at the
                # next overflow: the stepped path's poll there forgets the old write's time.
                self._eeprom_ready.due = None
            fw = self.fw
            timer = self.timer
            # Overflows before that one: the first at which the tick is due.
            span = ((io_at if io_at is not None else last + OVERFLOW_CYCLES) - overflow) // OVERFLOW_CYCLES
            due_at = self._first_due(fw, span)
            if due_at is not None:
                at = overflow + due_at * OVERFLOW_CYCLES
                self._jump_timer(due_at + 1)
                self._tick(fw, at, timer.millis, on_tick)
                self._overflow = at + OVERFLOW_CYCLES
                continue
            if io_at is None:
                self._jump_timer((last - overflow) // OVERFLOW_CYCLES + 1)
                self._overflow = last + OVERFLOW_CYCLES
                continue
            self._jump_timer((io_at - overflow) // OVERFLOW_CYCLES + 1)
            if arrived is not None and arrived <= io_at:
                self._receive(fw, io_at)
            fw = self.fw
            if writing or fw.state.eeBusy or self._eeprom_ready.due is not None:
                self._eeprom_ready.poll(fw.state, io_at)
            millis = timer.millis
            if fw.due(millis):
                self._tick(fw, io_at, millis, on_tick)
            self._overflow = io_at + OVERFLOW_CYCLES
        self._advance_to(end_cycle)
        self.cycle = max(self.cycle, end_cycle)

    def _reset_due(self, end_cycle: int) -> bool:
        """A ``reset`` fault due by the next overflow (and by ``end_cycle``): the plant
        brought to its cycle and the board reset there. Whether one was."""
        resets = self._resets
        if not resets or resets[0] > min(self._overflow, end_cycle):
            return False
        cycle = resets.pop(0)
        self._advance_to(cycle)
        self.cycle = max(self.cycle, cycle)
        self.reset()
        return True

    def _jump_timer(self, overflows: int) -> None:
        """``overflows`` Timer0 overflows at once (``millis_after``), on the same object."""
        timer = self.timer
        total = timer.fract + FRACT_INC * overflows
        timer.millis = (timer.millis + MILLIS_INC * overflows + total // FRACT_MAX) & 0xFFFFFFFF
        timer.fract = total % FRACT_MAX

    def _first_due(self, fw: Firmware, span: int) -> int | None:
        """Of the next ``span`` overflows (0: the next), the first at which ``fw.due``
        holds, or None: ``Firmware.due_after`` says how many ms from now the tick falls
        due, and Timer0's model (``millis_after``) the overflow at which ``millis()``
        has moved that far (``stepped=True`` asks ``due`` at every overflow instead;
        tests/sim/test_sim_speed.py holds the two paths to the same runs)."""
        if span <= 0:
            return None
        f0 = self.timer.fract
        # ms millis() moves in the next k overflows: MILLIS_INC * k + (f0 + FRACT_INC * k) // FRACT_MAX
        # Asked first after the next overflow (``due`` is not monotone across the
        # millis() just before it: a lastControlTime a ms ahead of now is not due now).
        first = MILLIS_INC + (f0 + FRACT_INC) // FRACT_MAX
        need = fw.due_after((self.timer.millis + first) & 0xFFFFFFFF)
        if need == 0:
            return 0
        k = max(1, need * FRACT_MAX // (MILLIS_INC * FRACT_MAX + FRACT_INC))
        need += first
        while MILLIS_INC * (k + 1) + (f0 + FRACT_INC * (k + 1)) // FRACT_MAX < need:
            k += 1
        while k > 1 and MILLIS_INC * k + (f0 + FRACT_INC * k) // FRACT_MAX >= need:
            k -= 1
        return k if k < span else None

    def _receive(self, fw: Firmware, overflow: int) -> None:
        """The bytes that have arrived by ``overflow`` go through ``processByte``."""
        data = self._rx.take(overflow)
        masked = self._masked()
        if masked:
            self._advance_to(overflow)
        out = fw.feed(data)
        if out:
            self.output.append((overflow, out))
        if masked:
            self._unmask_cleared(overflow)

    def _masked(self) -> bool:
        """Whether the storm guard masks an encoder now."""
        return bool(self._left.decoder.storm or self._right.decoder.storm)

    def _inhibits_at(self, cycle: int) -> int:
        """``inhibit_bits`` once the changes due by ``cycle`` are made."""
        due = self._inhibits_due
        while due and due[0].at <= cycle / F_CPU:
            change = due.pop(0)
            if change.number == LEVER_INPUT:
                self.plant.set_brake_lever(change.active)
            else:
                self.inhibit_bits = change.applied_to(self.inhibit_bits)
        return self.inhibit_bits

    def _inputs_at(self, cycle: int) -> int:
        """The tick's input pins at ``cycle`` (``control_tick``'s ``inputs``): the
        inhibit inputs, the brake driver's status and its manual release, from the plant."""
        bits = self._inhibits_at(cycle)
        plant = self.plant
        return bits | (4 if plant.brake_status_low else 0) | (8 if plant.brake_lever else 0)

    def _tick(self, fw: Firmware, overflow: int, millis: int,
              on_tick: Callable[[float], None] | None) -> None:
        """The control tick at ``overflow``: the plant brought to it, the latched counts
        in, PWM/DIR out to the plant."""
        self._advance_to(overflow)
        true_l, true_r = self._true_counts()
        left, right = self._left, self._right
        dl, dr = left.decoder, right.decoder
        out = fw.tick(millis, left.count(true_l), right.count(true_r), dl.illegal, dr.illegal, None,
                      int(dl.storm), int(dr.storm),
                      inputs=self._inputs_at(overflow), supply=self.supply_counts(overflow),
                      current_l=self._currents[0], current_r=self._currents[1])
        # the ADC interrupt's conversions of the motors' currents, just after the tick began
        mv = plant_current_millivolts(self.plant)
        self._currents = (adc_counts(mv["left"]), adc_counts(mv["right"]))
        s = fw.state
        self.plant.set_drive(s.pwmL, s.dirL, s.pwmR, s.dirR)
        self.plant.set_brake(bool(s.brakeReleased))
        self.output.append((overflow, out))
        self.last_tick_cycle = overflow
        if on_tick:
            on_tick(overflow / F_CPU)

    def _run_stepped(self, end_cycle: int, on_tick: Callable[[float], None] | None = None) -> None:
        """The reference path of ``run_until``: every Timer0 overflow in turn, ``due``
        asked at each (as before the loop was event-driven; tests/sim/test_sim_speed.py
        checks that both paths give the same bytes, ticks and states)."""
        while True:
            overflow = self._overflow
            if self._reset_due(end_cycle):
                continue
            if overflow > end_cycle:
                break
            fw = self.fw
            self.timer.overflow()
            if self._rx and self._rx.next_arrival() <= overflow:
                self._receive(fw, overflow)
            self._eeprom_ready.poll(fw.state, overflow)
            millis = self.timer.millis
            if fw.due(millis):
                self._tick(fw, overflow, millis, on_tick)
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
        self._currents = (C.CURRENT_ZERO_COUNTS, C.CURRENT_ZERO_COUNTS)
        self._eeprom_ready = ReadyInterrupt()
        self.timer = Timer0()
        self.boot_cycle = now
        self._overflow = now + FIRST_OVERFLOW_CYCLE
        self._rx.drop_before(now + SERIAL_READY_CYCLES)
        true = self._true_counts()
        for enc, count in zip(self._encoders.values(), true, strict=True):
            enc.reboot(count)
        s = self.fw.state
        self.plant.set_drive(s.pwmL, s.dirL, s.pwmR, s.dirR)
        self.plant.set_brake(bool(s.brakeReleased))
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
        edge_sides = [enc for enc in (self._left, self._right) if enc.needs_edges(lo, hi)]
        if not edge_sides:                 # the fast path: the counts come from the angles
            self.plant.advance_batch(n, self.dt, sampler=self.gyro)
            self._steps_done += n
            return
        previous = (self.plant.left.angle, self.plant.right.angle)
        angles = advance(self.plant, self.gyro, n, self.dt, angles=True)
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


def _overflow_at(cycle: int, overflow: int) -> int:
    """The first Timer0 overflow at or after ``cycle``, counting from ``overflow`` on."""
    if cycle <= overflow:
        return overflow
    return overflow + -(-(cycle - overflow) // OVERFLOW_CYCLES) * OVERFLOW_CYCLES


def advance(plant: Plant, gyro: Gyro | None, steps: int, dt: float, *, angles: bool = True
            ) -> np.ndarray | None:
    """``steps`` plant steps in one call of the kernel (``Plant.advance_batch``); the
    gyro samples the yaw rate of the step it falls in, the tick's samples at once
    (``Gyro.sample_steps``). Returns the wheel angles after each step (``0 x 2`` with
    ``angles=False``; None for no steps), valid until the plant's next step."""
    if steps <= 0:
        return None
    wheels, _ = plant.advance_batch(steps, dt, angles=angles, sampler=gyro)
    return wheels
