"""Differential proof: the Python port against the compiled firmware in simavr.

``record(trace)`` runs the trace on the virtual Mega and stops at the entry of every
``processByte`` and ``controlTick`` call. Each stop gives one firmware event (the
byte, or the tick's ``millis()``) and the controller state the previous event left,
read from SRAM by symbol, with PWM and DIR from the I/O registers.

``compare(recording)`` feeds the same events to
``wcdrive.firmware.final_control.Firmware``, started in the port's boot state with the
firmware's ``lastControlTime`` (the rest of the state after ``setup()`` is compared
too), and compares after every event:
every controller float bit for bit, every integer and flag, PWM duty and DIR per
motor, and, at the end, the whole TX byte stream. The only inputs the port takes
from the run are what the firmware's loop reads: the bytes, ``millis()`` at each
tick, the encoder and illegal-transition counts the tick latched (themselves checked
against the Python quadrature decoder run over the trace's edges) and the free RAM
loop() measured before the tick.

Two more checks cannot look away. Every byte the host sent must reach the firmware's
parser, or be lost where the firmware saw the loss: the harness models the USART's
two-frame FIFO and its data overrun (``VirtualMega.rx_lost``), the firmware's RX
interrupt counts a full ring and an overrun (``rxLost``) and marks the place, and
``loop()`` hands the mark to ``rxGap`` (an event here, given to the port as it is:
which bytes the chip loses is a matter of its timing, which the port does not model;
what the firmware does about it is). Bytes lost unseen are mismatches (``lost_bytes``).
And the firmware must keep ticking: a gap between control ticks longer than the period
plus ``TICK_TOLERANCE_MS``, or a ``millis()`` that does not follow the clock, is a
mismatch (``stalls``).

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

import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wcdrive.avr.f32 import bits
from wcdrive.boards.simavr.virtual_mega import F_CPU, RxLoss, VirtualMega
from wcdrive.firmware.constants import CONTROL_PERIOD_MS
from wcdrive.firmware.final_control import Firmware, reset_cause_name
from wcdrive.firmware.quadrature import ILLEGAL, QUAD_TABLE
from wcdrive.firmware.state import FLOAT_FIELDS, INPUT_FIELDS, INT_FIELDS, FirmwareState
from wcdrive.hil.traces import Trace

_WATCHED = FLOAT_FIELDS + INT_FIELDS + INPUT_FIELDS + ("rxLost",)

#: How long the Mega may run past the end of a trace to finish its last event (s).
FINISH_S = 0.02
#: How late a control tick may be before the gap counts as a stall (ms past the period).
TICK_TOLERANCE_MS = 10
#: How far ``millis()`` may drift from the cycle clock between two ticks (ms).
MILLIS_TOLERANCE_MS = 2
_BOOL_FIELDS = {"cmdSinceTick", "watchdogArmed", "emergencyStop", "ppmLost", "parked",
                "estopLatched", "tlmEnabled"}


@dataclass
class Event:
    """One firmware event: an entry to ``processByte`` (``arg`` the byte) or to
    ``controlTick`` (``arg`` its ``millis()``) at ``cycle``, with the globals, PWM and
    DIR it left (read at the next event)."""

    kind: str                 # "byte", "tick" or "gap" (rxGap: bytes lost before the next)
    arg: int                  # the byte, millis() passed to controlTick, or rxGap's count
    cycle: int
    after: dict[str, float | int] = field(default_factory=dict)
    pwm: tuple[int, int] = (0, 0)
    direction: tuple[int, int] = (1, 1)
    #: The EEPROM's contents it left, and the cycle at which ``after`` was read.
    eeprom: bytes = b""
    after_cycle: int = 0


@dataclass
class Recording:
    """One run on the virtual Mega: the trace, the globals after ``setup()``, every
    event, the TX bytes and the last cycle."""

    trace: Trace
    initial: dict[str, float | int]
    events: list[Event]
    tx: bytes
    end_cycle: int
    #: The resets after the power-on (``Recorder.reset``): (cycle, MCUSR after it, the
    #: globals at the first event after it: the new boot's state after ``setup()``).
    resets: list[tuple[int, int, dict[str, float | int]]] = field(default_factory=list)
    #: The cycle of each byte of ``tx`` (empty: not kept; then no reset may occur).
    tx_cycles: list[int] = field(default_factory=list)
    #: Every byte sent to the board: (the cycle it reached the USART, byte), in order.
    rx_wire: list[tuple[int, int]] = field(default_factory=list)
    #: The bytes the USART lost (overrun, or sent while the receiver was off).
    rx_lost: list[RxLoss] = field(default_factory=list)
    #: Whether ``rx_wire`` is complete: False for recordings that did not log it (then
    #: the delivery check is skipped).
    rx_logged: bool = False
    #: The EEPROM's contents after ``setup()`` (b"": not kept), and the cycle of each
    #: entry to the EEPROM-ready interrupt (``eepromReady``: one byte of a ``save``
    #: written), which is not an event of its own: it may come in the middle of one.
    initial_eeprom: bytes = b""
    eeprom_writes: list[int] = field(default_factory=list)


@dataclass
class Mismatch:
    """One difference: the event's index (-1: the state after ``setup()``), the ticks so
    far, the field and both values."""

    event_index: int
    tick: int
    field: str
    port: str
    firmware: str

    def __str__(self) -> str:
        return (f"event {self.event_index} (tick {self.tick}): {self.field} "
                f"port={self.port} firmware={self.firmware}")


@dataclass
class Report:
    """What ``compare`` found: events, ticks and values compared, the mismatches and the
    firmware's TX byte count; the received bytes lost unseen (``lost_bytes``, each also a
    mismatch), those lost and accounted for (``rx_lost``: a full ring or an overrun, seen
    by the firmware and the port alike; ``rx_off``: sent while the receiver was off,
    before ``Serial.begin`` or during a reset, or still in the ring at a reset), and the
    stalls of the control tick (each also a mismatch)."""

    events: int
    ticks: int
    fields_compared: int
    mismatches: list[Mismatch]
    tx_bytes: int
    lost_bytes: int = 0
    rx_lost: int = 0
    rx_off: int = 0
    stalls: int = 0


def _hexf(x: float) -> str:
    return f"{bits(x):#010x} ({x!r})"


class Recorder:
    """Runs a ``VirtualMega`` and logs every firmware event with the state it leaves:
    ``run_until(cycle)`` stops at each ``processByte``/``controlTick`` entry, reads the
    controller globals, PWM and DIR, and goes on."""

    def __init__(self, mega: VirtualMega) -> None:
        self.mega = mega
        self.events: list[Event] = []
        self.initial: dict[str, float | int] | None = None
        self.resets: list[tuple[int, int, dict[str, float | int]]] = []
        self._reset_pending: tuple[int, int] | None = None
        self._boot_state: dict[str, float | int] = {}
        self.initial_eeprom = b""
        self.eeprom_writes: list[int] = []
        self._eeprom = b""
        mega.break_on("processByte", "controlTick", "rxGap", "eepromReady")

    def reset(self, cause: str = "external") -> None:
        """Resets the Mega (``VirtualMega.reset``) after closing the last event with the
        state it left; the state at the next event is the new boot's."""
        self._close_last()
        done = self.mega.reset(cause)
        self._reset_pending = (done.cycle, done.mcusr)

    def _snapshot(self) -> tuple[dict[str, float | int], tuple[int, int], tuple[int, int]]:
        m = self.mega
        return (m.snapshot(_WATCHED), (m.pwm("left"), m.pwm("right")),
                (m.direction("left"), m.direction("right")))

    def _read_eeprom(self) -> bytes:
        """The EEPROM now (the same object as last time when it has not changed)."""
        image = self.mega.read_eeprom()
        if image != self._eeprom:
            self._eeprom = image
        return self._eeprom

    def _end_reset(self) -> None:
        """A reset is followed by an event (or the end): the state now is the new boot's."""
        if self._reset_pending is not None:
            self.resets.append((*self._reset_pending, self._boot_state))
            self._reset_pending = None

    def _close_last(self, at_event: bool = True) -> None:
        """Reads the state the last event left. ``at_event``: the run stopped at the next
        event; otherwise at the end of a stretch, perhaps inside setup(), so the state is
        not yet the one after setup()."""
        state, pwm, direction = self._snapshot()
        if self._reset_pending is not None:
            if at_event:
                self._boot_state = state      # the last event before the reset stays as it was
        elif self.events:
            last = self.events[-1]
            last.after, last.pwm, last.direction = state, pwm, direction
            last.eeprom, last.after_cycle = self._read_eeprom(), self.mega.cycle
        elif self.initial is None and at_event:
            self.initial = state
            self.initial_eeprom = self._read_eeprom()

    def run_until(self, cycle: int) -> None:
        """Runs the Mega to ``cycle``, logging every event on the way."""
        mega = self.mega
        while mega.run_to_break(cycle):
            hit = mega.hit_log[-1]
            if hit.function == "eepromReady":
                self.eeprom_writes.append(hit.cycle)     # not an event: see Recording
                continue
            self._close_last()
            self._end_reset()
            kind = {"processByte": "byte", "controlTick": "tick"}.get(hit.function, "gap")
            arg = hit.arg if kind == "tick" else (hit.arg >> 16) & 0xFF   # the byte; rxGap's lost
            self.events.append(Event(kind, arg, hit.cycle))
        self._close_last(at_event=False)

    def recording(self, trace: Trace) -> Recording:
        """What was logged so far, as the ``Recording`` of ``trace``. The last event may
        still be running where the trace ends (a tick takes a few ms): the Mega runs on
        until the next event starts, or ``FINISH_S`` at most, so that the state it left
        is complete; that next event and anything after it are not part of the run."""
        end = self.mega.cycle
        if self.events and self._reset_pending is None:
            self.mega.run_to_break(end + round(FINISH_S * F_CPU))
            self._close_last(at_event=False)
        if self.initial is None:
            self.initial = self._snapshot()[0]     # no event yet: the state now
        if self._reset_pending is not None:
            self._boot_state = self._snapshot()[0]  # no event since the last reset
        tx = bytes(b for _, b in self.mega.tx_log)
        self._end_reset()
        resets = list(self.resets)
        tx_cycles = [c for c, _ in self.mega.tx_log]
        mega = self.mega
        return Recording(trace, self.initial, self.events, tx, end, resets, tx_cycles,
                         list(mega.rx_wire), [x for x in mega.rx_lost if x.cycle < end], rx_logged=True,
                         initial_eeprom=self.initial_eeprom or self._read_eeprom(),
                         eeprom_writes=list(self.eeprom_writes))


def record(trace: Trace, elf: str | Path | None = None) -> Recording:
    """Runs ``trace`` on the firmware ``elf`` (default: the bundled one, built if
    needed) in simavr and logs every event."""
    mega = VirtualMega(elf, millis_start=trace.millis_start, eeprom=trace.eeprom)
    try:
        for t, data in trace.serial:
            mega.send(data, at=round(t * F_CPU))
        for side, train in trace.encoders.items():
            mega.encoder_edges(side, train)
        recorder = Recorder(mega)
        for t, cause in sorted(trace.resets):
            recorder.run_until(round(t * F_CPU))
            recorder.reset(cause)
        recorder.run_until(round(trace.duration * F_CPU))
        return recorder.recording(trace)
    finally:
        mega.close()


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
            # freeRam is measured by loop() just before the call: the state at entry.
            before = events[i - 1].after if i > 0 else recording.initial
            tx += fw.tick(ev.arg, latched["encTickL"], latched["encTickR"], latched["illTickL"],
                          latched["illTickR"], free_ram=int(before["freeRam"]),
                          storm_l=latched["stormTickL"], storm_r=latched["stormTickR"],
                          rx_lost=int(ev.after["rxLostTick"]))
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


def _boots(recording: Recording) -> list[tuple[int, int]]:
    """The cycle spans [start, end) of each boot of the run."""
    cuts = [c for c, _, _ in recording.resets]
    return list(zip([0, *cuts], [*cuts, recording.end_cycle], strict=True))


def _stalls(recording: Recording) -> list[Mismatch]:
    """The control tick must keep running, boot by boot: no gap between ticks (or from a
    boot to its first tick, or from the last tick to the end) longer than the period
    plus ``TICK_TOLERANCE_MS`` (a boot's first tick may also take setup()'s time, the
    period again), and ``millis()`` moving with the clock between ticks."""
    out: list[Mismatch] = []
    per_ms = F_CPU // 1000
    limit = (CONTROL_PERIOD_MS + TICK_TOLERANCE_MS) * per_ms
    ticks = [(i, ev) for i, ev in enumerate(recording.events) if ev.kind == "tick"]
    count = 0
    for start, end in _boots(recording):
        mine = [(i, ev) for i, ev in ticks if start <= ev.cycle < end]
        marks = [(-1, start), *((i, ev.cycle) for i, ev in mine), (-1, end)]
        for k, ((where, a), (_, b)) in enumerate(itertools.pairwise(marks)):
            allowed = limit * 2 if k == 0 else limit
            if b - a > allowed:
                out.append(Mismatch(where, count + k, "stall",
                                    f"a control tick every {CONTROL_PERIOD_MS} ms",
                                    f"none for {(b - a) / per_ms:.1f} ms (cycles {a}..{b})"))
        for (_, e0), (j, e1) in itertools.pairwise(mine):
            clock_ms = (e1.cycle - e0.cycle) / per_ms
            millis_ms = (e1.arg - e0.arg) & 0xFFFFFFFF
            if abs(millis_ms - clock_ms) > MILLIS_TOLERANCE_MS:
                out.append(Mismatch(j, count, "stall", f"millis() +{clock_ms:.1f} (the clock)",
                                    f"millis() +{millis_ms}"))
        count += len(mine)
    return out


@dataclass
class _Delivery:
    mismatches: list[Mismatch] = field(default_factory=list)
    lost_bytes: int = 0
    rx_lost: int = 0
    rx_off: int = 0


def _delivery(recording: Recording) -> _Delivery:
    """Every byte the host sent, boot by boot, against what reached ``processByte``: the
    firmware's bytes must be the host's less those lost, and each loss must be marked
    (an ``rxGap`` event before the next byte) and counted (``rxLost``); see the module
    docstring."""
    d = _Delivery()
    lost = {loss.index: loss for loss in recording.rx_lost}
    d.rx_off = sum(1 for loss in recording.rx_lost if loss.cause == "receiver_off")
    events = recording.events
    count_before = [recording.initial] + [booted for _, _, booted in recording.resets]
    for k, (start, end) in enumerate(_boots(recording)):
        # The host's bytes that reached the USART in this boot and were not lost there:
        # (index, byte, carries DOR: the first after a run of overrun losses).
        host: list[tuple[int, int, bool]] = []
        for index, (cycle, byte) in enumerate(recording.rx_wire):
            if start <= cycle < end and index not in lost:
                prev = lost.get(index - 1)
                host.append((index, byte, prev is not None and prev.cause == "overrun"))
        wire = bytes(b for _, b, _ in host)
        mine = [(i, ev) for i, ev in enumerate(events) if start <= ev.cycle < end and ev.kind != "tick"]
        # (first event, losses counted before it: rxGap's count, -1 none, bytes)
        segments: list[tuple[int, int, bytearray]] = []
        for i, ev in mine:
            if ev.kind == "gap":
                segments.append((i, ev.arg, bytearray()))
            elif not segments:
                segments.append((i, -1, bytearray([ev.arg])))
            else:
                segments[-1][2].append(ev.arg)
        p = ring_drops = 0
        dor_read = 0
        for i, counted_here, data in segments:
            gap = counted_here >= 0
            if not data:
                continue
            # rxGap's count says how many bytes the ring dropped here (less one if the
            # next byte carries an overrun); 255 is a saturated count: search instead.
            at = -1
            if 0 <= counted_here < 255:
                for dor in (1, 0):
                    k = p + counted_here - dor
                    if p <= k < len(host) and host[k][2] == bool(dor) and wire.startswith(bytes(data), k):
                        at = k
                        break
            if at < 0:
                at = wire.find(bytes(data), p)
            if at < 0:
                d.mismatches.append(Mismatch(i, 0, "RX", "the host's bytes", f"{bytes(data)[:40]!r} "
                                             f"(boot {k}): not what was sent"))
                d.lost_bytes += len(data)
                break
            skipped = at - p
            dor_first = host[at][2]
            dor_inside = [host[j][0] for j in range(at + 1, at + len(data)) if host[j][2]]
            if not gap and (skipped or dor_first):
                d.mismatches.append(Mismatch(i, 0, "RX", "a gap mark (rxGap)",
                                             f"{skipped or 'overrun'} bytes lost unseen before "
                                             f"byte {host[at][0]} (boot {k})"))
                d.lost_bytes += max(skipped, 1)
            elif gap and not skipped and not dor_first:
                d.mismatches.append(Mismatch(i, 0, "RX", "no loss", f"a gap mark before byte "
                                             f"{host[at][0]} (boot {k})"))
            if dor_inside:
                d.mismatches.append(Mismatch(i, 0, "RX", "a gap mark (rxGap)",
                                             f"overrun unseen before byte {dor_inside[0]} (boot {k})"))
                d.lost_bytes += len(dor_inside)
            ring_drops += skipped
            dor_read += int(dor_first) + len(dor_inside)
            p = at + len(data)
        # What the firmware counted: every ring drop and overrun before the last byte it
        # read, and perhaps some of the bytes after it (still in the ring or USART, or
        # dropped); the bytes still in flight at a reset are lost with the reset.
        in_boot = [ev for ev in events if start <= ev.cycle < end]
        final = in_boot[-1].after if in_boot and in_boot[-1].after else count_before[k]
        counted = int(final.get("rxLost", 0))
        trailing = len(host) - p
        expected = ring_drops + dor_read
        if not expected <= counted <= expected + trailing + sum(1 for _, _, dor in host[p:] if dor):
            d.mismatches.append(Mismatch(len(events), 0, "rxLost", f"{expected} (+ up to {trailing})",
                                         f"{counted} (boot {k})"))
        d.rx_lost += counted
        if k < len(recording.resets):
            d.rx_off += max(0, trailing - max(0, counted - expected))
    return d


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
