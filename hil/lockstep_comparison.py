"""The comparing half of the lock-step proof: ``compare(recording)`` replays a
``Recording``'s events on the port and gives a ``Report`` of every difference;
``initial_state(recording)`` is the port's state after ``setup()`` for that run.

``compare`` feeds the recorded events to ``wcdrive.firmware.final_control.Firmware``,
started in the port's boot state with the firmware's ``lastControlTime`` (the rest of
the state after ``setup()`` is compared too), and compares after every event:
every controller float bit for bit, every integer and flag, PWM duty and DIR per
motor, and, at the end, the whole TX byte stream. The only inputs the port takes
from the run are what the firmware's loop reads: the bytes, ``millis()`` at each
tick, the encoder and illegal-transition counts the tick latched (themselves checked
against the Python quadrature decoder run over the trace's edges) and the free RAM
loop() measured before the tick, the supply sense's ADC count it latched (checked
against the trace's millivolts at A0, ``Trace.supply``), and the globals the harness
set at a tick's entry (``Trace.pokes``). The bytes' delivery and the tick's liveness are
checked too (``wcdrive.hil.lockstep_liveness``).

A run may reset the board (``VirtualMega.reset``, or its watchdog): at each reset the
port starts again from ``setup()`` with the new boot's ``lastControlTime`` and the
BOOT line of the reset's cause (MCUSR); the state the firmware shows right after its
new ``setup()`` is compared with that, the encoder counts are checked from the count
at the reset on, and the TX stream is compared boot by boot (what sat in the TX ring
at the reset is lost on the chip, so each boot's bytes only need to start the port's).

The EEPROM is compared too, after every event, and the port's own EEPROM goes through
each reset (the new boot loads what the port wrote; ``Trace.eeprom`` is the image at
power-on). A ``save`` writes its block one byte per EEPROM-ready interrupt
(``eepromReady``, 3.4 ms apart); the harness logs each entry
(``Recording.eeprom_writes``) and the port takes those that came before the state was
read, after the event they fell in (they touch only the EEPROM, ``eeNext`` and
``eeBusy``, which no event but ``save`` reads). A ``save`` whose own parse the last
interrupt of the previous save interrupts, before it reads ``eeBusy``, is accepted
by the firmware and refused ``busy`` by the port: a mismatch that is the harness's,
not seen so far (the window is a few hundred cycles once per save).
"""

from __future__ import annotations

import numpy as np

from wcdrive.avr.f32 import bits, f32
from wcdrive.boards.current_sense import ZERO_MV as CURRENT_ZERO_MV
from wcdrive.boards.inhibits import InhibitChange, active_bits
from wcdrive.boards.simavr.virtual_mega import F_CPU
from wcdrive.boards.supply_sense import NOMINAL_MV, adc_counts
from wcdrive.firmware.constants import CURRENT_ZERO_COUNTS
from wcdrive.firmware.final_control import Firmware, reset_cause_name
from wcdrive.firmware.quadrature import ILLEGAL, QUAD_TABLE
from wcdrive.firmware.state import FLOAT_FIELDS, INT_FIELDS, FirmwareState
from wcdrive.hil.lockstep_liveness import _Delivery, _delivery, _stalls
from wcdrive.hil.lockstep_recording import Event, Recording
from wcdrive.hil.lockstep_report import Mismatch, Report
from wcdrive.hil.traces import Trace

__all__ = ["compare", "initial_state"]

_BOOL_FIELDS = {"cmdSinceTick", "watchdogArmed", "emergencyStop", "ppmLost", "parked",
                "estopLatched", "tlmEnabled"}


def _hexf(x: float) -> str:
    return f"{bits(x):#010x} ({x!r})"


def initial_state(recording: Recording) -> FirmwareState:
    """The port's state after setup(): the default state with the boot millis() and the
    parameters ``setup()`` loaded from the trace's EEPROM."""
    return Firmware(boot_millis=int(recording.initial["lastControlTime"]),
                    eeprom=recording.trace.eeprom).state


def _decoded_counts(trace: Trace, side: str) -> tuple[tuple[np.ndarray, np.ndarray],
                                                     tuple[np.ndarray, np.ndarray]]:
    """(count, edge cycle) and (illegal-transition count, edge cycle) after each edge, by
    the Python decoder."""
    train = trace.encoders.get(side)
    if train is None or train.times.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return (empty, empty), (empty, empty)
    states = train.states.astype(np.int64)
    previous = np.concatenate(([0b11], states[:-1]))
    transitions = (previous << 2) | states
    table = np.array([0 if v == ILLEGAL else v for v in QUAD_TABLE])
    illegal = np.array([1 if v == ILLEGAL else 0 for v in QUAD_TABLE])
    cycles = np.round(train.times * F_CPU).astype(np.int64)
    return (np.cumsum(table[transitions]), cycles), (np.cumsum(illegal[transitions]), cycles)


def compare(recording: Recording) -> Report:
    """Replays the recording's events on the port and lists every difference (the
    module docstring says what is compared)."""
    fw = Firmware(boot_millis=int(recording.initial["lastControlTime"]), eeprom=recording.trace.eeprom)
    mismatches: list[Mismatch] = []
    fields_compared = 0
    # The state right after setup() must be the port's boot state.
    for name, port_value, fw_value in _differences(fw.state, recording.initial):
        mismatches.append(Mismatch(-1, 0, name, port_value, fw_value))
    mismatches.extend(_eeprom_differences(-1, 0, fw.state.eeprom, recording.initial_eeprom))
    writes = list(recording.eeprom_writes)
    w = 0
    boots = [bytearray(fw.boot_output())]           # the port's TX, boot by boot
    decoded = {side: _decoded_counts(recording.trace, side) for side in ("left", "right")}
    inhibits = [InhibitChange(t, number, active) for t, number, active in recording.trace.inhibits]
    supply = _pin_timeline(recording.trace.supply, NOMINAL_MV)
    currents = {side: _pin_timeline([(t, mv) for t, s, mv in recording.trace.currents if s == side],
                                    CURRENT_ZERO_MV) for side in ("left", "right")}
    last_tick: int | None = None         # the cycle of the last tick since the boot
    # What the decoder had counted when the firmware's counts started from 0 (at
    # setup(), somewhere between a reset and the first event after it): the candidates.
    offsets: dict[tuple[str, int], set[int]] = {(side, k): {0} for side in ("left", "right") for k in (0, 1)}
    resets = list(recording.resets)
    masked: dict[str, tuple[int, int, int]] = {}     # side: (cycle, count, illegal) frozen
    # The tick before a storm is latched may hold edges faster than the interrupt (the
    # storm's first window, before the guard masks the encoder): merged edges the decoder
    # does not model. Its counts are untrusted by design (the storm stops the chair): no
    # decoder check for that side at that tick.
    before_storm = _ticks_before_storm(recording.events)
    ticks = 0
    events = recording.events
    for i, ev in enumerate(events):
        tx = boots[-1]
        if ev.kind == "byte":
            tx += fw.feed(bytes([ev.arg]))
        elif ev.kind == "gap":
            fw.rx_gap(ev.arg)
        else:
            ticks += 1
            latched = {name: int(ev.after[name])
                       for name in ("encTickL", "encTickR", "illTickL", "illTickR", "stormTickL",
                                    "stormTickR")}
            exit_cycle = events[i + 1].cycle if i + 1 < len(events) else recording.end_cycle
            for side, suffix in (("left", "L"), ("right", "R")):
                if latched["stormTick" + suffix]:
                    # Masked by the storm guard: its count stopped early. Remember the
                    # frozen counts and when: a "reset" unmasks it and counting goes on
                    # from there.
                    masked[side] = (ev.cycle, latched["encTick" + suffix], latched["illTick" + suffix])
                    continue
                if (i, side) in before_storm:
                    continue
                if side in masked:
                    # Unmasked since the last tick: the ISR took up counting from the
                    # frozen counts at the unmask, somewhere between the two ticks.
                    since, frozen_count, frozen_illegal = masked.pop(side)
                    for k, frozen in ((0, frozen_count), (1, frozen_illegal)):
                        counts, cycles = decoded[side][k]
                        lo = int(np.searchsorted(cycles, since, "right"))
                        hi = int(np.searchsorted(cycles, ev.cycle, "right"))
                        base = {int(counts[lo - 1]) if lo > 0 else 0}
                        base.update(int(c) for c in counts[lo:hi])
                        offsets[(side, k)] = {c - frozen for c in base}
                for what, k in (("encTick", 0), ("illTick", 1)):
                    value = latched[what + suffix]
                    if not any(_count_possible(decoded[side][k], value + offset, ev.cycle, exit_cycle)
                               for offset in offsets[(side, k)]):
                        mismatches.append(Mismatch(i, ticks, f"{what} {side}",
                                                   "decoder disagrees", str(value)))
            # The input pins the tick read (the inhibit inputs, the brake's status): what
            # the trace put on the pins between the tick's entry and its exit, at any
            # moment (a pulse shorter than the window may be all the tick saw).
            read_bits = int(ev.after["inhibitTick"])
            inputs = (read_bits & 3) | int(ev.after["brakeStatusTick"]) << 2 | (read_bits & 4) << 1
            entry, exit_s = ev.cycle / F_CPU, exit_cycle / F_CPU
            read = {active_bits(inhibits, t)
                    for t in (entry, *(c.at for c in inhibits if entry < c.at <= exit_s))}
            if inputs not in read:
                mismatches.append(Mismatch(i, ticks, "inhibitTick, brakeStatusTick",
                                           "the trace's pins disagree", str(inputs)))
            # The supply count the tick latched: simavr converts A0's millivolts when the
            # tick reads ADCL, somewhere between its entry and its exit.
            supply_count = int(ev.after["supplyTick"])
            if supply_count not in _supply_counts(supply, ev.cycle, exit_cycle):
                mismatches.append(Mismatch(i, ticks, "supplyTick", "the trace's supply disagrees",
                                           str(supply_count)))
            # The motors' current counts: the ADC interrupt converted A1 and A2 after the
            # last tick began (the globals' CURRENT_ZERO_COUNTS before the boot's first).
            current_counts = (int(ev.after["currentTickL"]), int(ev.after["currentTickR"]))
            for side, count in zip(("left", "right"), current_counts, strict=True):
                possible = ({CURRENT_ZERO_COUNTS} if last_tick is None
                            else _supply_counts(currents[side], last_tick, ev.cycle))
                if count not in possible:
                    mismatches.append(Mismatch(i, ticks, f"currentTick {side}",
                                               "the trace's current sense disagrees", str(count)))
            last_tick = ev.cycle
            # freeRam is measured by loop() just before the call: the state at entry.
            before = events[i - 1].after if i > 0 else recording.initial
            for name, value in ev.poke.items():     # what the harness set at the entry
                setattr(fw.state, name, f32(value) if name in FLOAT_FIELDS else int(value))
            tx += fw.tick(ev.arg, latched["encTickL"], latched["encTickR"], latched["illTickL"],
                          latched["illTickR"], free_ram=int(before["freeRam"]),
                          storm_l=latched["stormTickL"], storm_r=latched["stormTickR"],
                          rx_lost=int(ev.after["rxLostTick"]), inputs=inputs, supply=supply_count,
                          current_l=current_counts[0], current_r=current_counts[1])
        # The EEPROM-ready interrupts that came before the state was read: their writes
        # touch nothing the event does, so their order within it does not matter.
        while w < len(writes) and writes[w] < ev.after_cycle:
            fw.eeprom_ready()
            w += 1
        diffs = _differences(fw.state, ev.after)
        fields_compared += len(FLOAT_FIELDS) + len(INT_FIELDS) + 4
        for name, port_value, fw_value in diffs:
            mismatches.append(Mismatch(i, ticks, name, port_value, fw_value))
        if ev.eeprom:
            fields_compared += 1
            mismatches.extend(_eeprom_differences(i, ticks, fw.state.eeprom, ev.eeprom))
        port_io = ((fw.state.pwmL, fw.state.pwmR), (fw.state.dirL, fw.state.dirR))
        if port_io != (ev.pwm, ev.direction):
            mismatches.append(Mismatch(i, ticks, "pins (pwm, dir)", str(port_io),
                                       str((ev.pwm, ev.direction))))
        next_cycle = events[i + 1].cycle if i + 1 < len(events) else recording.end_cycle
        while resets and resets[0][0] <= next_cycle:
            # The board reset before the next event: the port starts again from setup()
            # and must match the new boot's state.
            cycle, mcusr, booted = resets.pop(0)
            masked.clear()                  # the new boot counts from 0, unmasked
            last_tick = None
            # The EEPROM survives: the new boot loads what the port itself wrote.
            fw = Firmware(boot_millis=int(booted["lastControlTime"]), eeprom=fw.state.eeprom,
                          cause=reset_cause_name(mcusr))
            boots.append(bytearray(fw.boot_output()))
            for side in ("left", "right"):
                for k in (0, 1):
                    counts, cycles = decoded[side][k]
                    lo = int(np.searchsorted(cycles, cycle, "right"))
                    hi = int(np.searchsorted(cycles, next_cycle, "right"))
                    offsets[(side, k)] = {int(counts[lo - 1]) if lo > 0 else 0}
                    offsets[(side, k)].update(int(c) for c in counts[lo:hi])
            for name, port_value, fw_value in _differences(fw.state, booted):
                mismatches.append(Mismatch(i, ticks, f"{name} (after the reset)", port_value, fw_value))
    # The TX stream, boot by boot: the firmware may still hold the tail of a boot's last
    # lines in its TX ring (lost at a reset, or not sent yet at the end).
    cuts = [c for c, _, _ in recording.resets]
    if cuts and len(recording.tx_cycles) != len(recording.tx):
        mismatches.append(Mismatch(len(events), ticks, "TX", "a reset without TX cycles", ""))
        cuts = []
    starts = [0] + [int(np.searchsorted(np.asarray(recording.tx_cycles), c, "left")) for c in cuts]
    ends = [*starts[1:], len(recording.tx)]
    for k, (lo, hi) in enumerate(zip(starts, ends, strict=True)):
        fw_tx = recording.tx[lo:hi]
        sent = bytes(boots[k]) if k < len(boots) else b""
        if not (sent.startswith(fw_tx) and len(sent) - len(fw_tx) < 256 + (256 if k < len(ends) - 1 else 0)):
            where = next((j for j, (a, b) in enumerate(zip(sent, fw_tx, strict=False)) if a != b),
                         min(len(sent), len(fw_tx)))
            mismatches.append(Mismatch(len(events), ticks, f"TX byte {where} (boot {k})",
                                       repr(sent[max(0, where - 20):where + 20]),
                                       repr(fw_tx[max(0, where - 20):where + 20])))
    stalls = _stalls(recording)
    mismatches.extend(stalls)
    delivery = _delivery(recording) if recording.rx_logged else _Delivery()
    mismatches.extend(delivery.mismatches)
    return Report(len(events), ticks, fields_compared, mismatches, len(recording.tx),
                  delivery.lost_bytes, delivery.rx_lost, delivery.rx_off, len(stalls))


def _ticks_before_storm(events: list[Event]) -> set[tuple[int, str]]:
    """(tick event index, side) of each tick right before the one that latched a storm."""
    out: set[tuple[int, str]] = set()
    last: dict[str, tuple[int, int]] = {}
    for i, ev in enumerate(events):
        if ev.kind != "tick" or not ev.after:
            continue
        for side, suffix in (("left", "L"), ("right", "R")):
            storm = int(bool(ev.after.get("stormTick" + suffix, 0)))
            previous = last.get(side)
            if storm and previous is not None and not previous[1]:
                out.add((previous[0], side))
            last[side] = (i, storm)
    return out


def _pin_timeline(changes: list[tuple[float, int]], start_mv: int) -> tuple[np.ndarray, np.ndarray]:
    """An analog pin's (s, mV) changes as (cycle, mV) arrays from power-on: ``start_mv``
    at cycle 0 (where the board starts), then each change at its cycle, in time order (a
    change is made after those before it at the same cycle)."""
    ordered = sorted(((round(t * F_CPU), int(mv)) for t, mv in changes), key=lambda c: c[0])
    cycles = np.array([0] + [c for c, _ in ordered], dtype=np.int64)
    mvs = np.array([start_mv] + [mv for _, mv in ordered], dtype=np.int64)
    return cycles, mvs


def _supply_counts(timeline: tuple[np.ndarray, np.ndarray], start: int, stop: int) -> set[int]:
    """The ADC counts a read of an analog input at some cycle in [start, stop] may give:
    the mV in force at ``start`` (the tick's entry) and every mV set until ``stop`` (its
    exit)."""
    cycles, mvs = timeline
    lo = int(np.searchsorted(cycles, start, "right")) - 1
    hi = int(np.searchsorted(cycles, stop, "right"))
    return {adc_counts(int(mv)) for mv in mvs[max(lo, 0):hi]}


def _count_possible(decoded: tuple[np.ndarray, np.ndarray], count: int, start: int,
                    stop: int) -> bool:
    """Was ``count`` the decoder's count at some cycle in [start, stop]? Edges that land
    while the tick runs may or may not be latched, so every count in that window is."""
    counts, cycles = decoded
    if counts.size == 0:
        return count == 0
    hi = int(np.searchsorted(cycles, stop, "right"))
    # An edge at cycle c is seen by the ISR a few cycles later: allow 200 cycles of latency.
    lo = int(np.searchsorted(cycles, start - 200, "left"))
    candidates = {int(counts[lo - 1]) if lo > 0 else 0}
    candidates.update(int(c) for c in counts[lo:hi])
    return count in candidates


def _eeprom_differences(i: int, tick: int, port: bytes | bytearray, fw: bytes) -> list[Mismatch]:
    """The first EEPROM byte where the port's image and the firmware's differ, if any."""
    if not fw or bytes(port) == fw:
        return []
    at = next((j for j, (a, b) in enumerate(zip(port, fw, strict=False)) if a != b), min(len(port), len(fw)))
    return [Mismatch(i, tick, f"EEPROM byte {at}", bytes(port[at:at + 8]).hex(), fw[at:at + 8].hex())]


def _differences(state: FirmwareState, fw: dict[str, float | int]) -> list[tuple[str, str, str]]:
    out = []
    for name in FLOAT_FIELDS:
        a, b = getattr(state, name), float(fw[name])
        if bits(a) != bits(b):
            out.append((name, _hexf(a), _hexf(b)))
    for name in INT_FIELDS:
        a, b = int(getattr(state, name)), int(fw[name])
        if name in _BOOL_FIELDS:
            a, b = int(bool(a)), int(bool(b))
        if name in ("encTickL", "encTickR", "prevEncL", "prevEncR"):
            a &= 0xFFFFFFFF
            b &= 0xFFFFFFFF
        if a != b:
            out.append((name, f"{a:#x}", f"{b:#x}"))
    return out
