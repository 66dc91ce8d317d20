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

A run may reset the board (``VirtualMega.reset``, or its watchdog): at each reset the
port starts again from ``setup()`` with the new boot's ``lastControlTime`` and the
BOOT line of the reset's cause (MCUSR); the state the firmware shows right after its
new ``setup()`` is compared with that, the encoder counts are checked from the count
at the reset on, and the TX stream is compared boot by boot (what sat in the TX ring
at the reset is lost on the chip, so each boot's bytes only need to start the port's).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wcdrive.avr.f32 import bits
from wcdrive.boards.simavr.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware.final_control import Firmware, boot_line, reset_cause_name
from wcdrive.firmware.quadrature import ILLEGAL, QUAD_TABLE
from wcdrive.firmware.state import FLOAT_FIELDS, INPUT_FIELDS, INT_FIELDS, FirmwareState
from wcdrive.hil.traces import Trace

_WATCHED = FLOAT_FIELDS + INT_FIELDS + INPUT_FIELDS + ("txDropped",)
_BOOL_FIELDS = {"cmdSinceTick", "watchdogArmed", "emergencyStop", "ppmLost", "parked",
                "estopLatched", "tlmEnabled"}


@dataclass
class Event:
    """One firmware event: an entry to ``processByte`` (``arg`` the byte) or to
    ``controlTick`` (``arg`` its ``millis()``) at ``cycle``, with the globals, PWM and
    DIR it left (read at the next event)."""

    kind: str                 # "byte" or "tick"
    arg: int                  # the byte, or millis() passed to controlTick
    cycle: int
    after: dict[str, float | int] = field(default_factory=dict)
    pwm: tuple[int, int] = (0, 0)
    direction: tuple[int, int] = (1, 1)


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
    firmware's TX byte count."""

    events: int
    ticks: int
    fields_compared: int
    mismatches: list[Mismatch]
    tx_bytes: int


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
        mega.break_on("processByte", "controlTick")

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

    def _end_reset(self) -> None:
        """A reset is followed by an event (or the end): the state now is the new boot's."""
        if self._reset_pending is not None:
            self.resets.append((*self._reset_pending, self._boot_state))
            self._reset_pending = None

    def _close_last(self) -> None:
        state, pwm, direction = self._snapshot()
        if self._reset_pending is not None:
            self._boot_state = state          # the last event before the reset stays as it was
        elif self.events:
            last = self.events[-1]
            last.after, last.pwm, last.direction = state, pwm, direction
        elif self.initial is None:
            self.initial = state

    def run_until(self, cycle: int) -> None:
        """Runs the Mega to ``cycle``, logging every event on the way."""
        mega = self.mega
        while mega.run_to_break(cycle):
            hit = mega.hit_log[-1]
            self._close_last()
            self._end_reset()
            kind = "byte" if hit.function == "processByte" else "tick"
            arg = (hit.arg >> 16) & 0xFF if kind == "byte" else hit.arg
            self.events.append(Event(kind, arg, hit.cycle))
        self._close_last()

    def recording(self, trace: Trace) -> Recording:
        """What was logged so far, as the ``Recording`` of ``trace``."""
        assert self.initial is not None, "run_until() first"
        tx = bytes(b for _, b in self.mega.tx_log)
        self._end_reset()
        resets = list(self.resets)
        tx_cycles = [c for c, _ in self.mega.tx_log]
        return Recording(trace, self.initial, self.events, tx, self.mega.cycle, resets, tx_cycles)


def record(trace: Trace, elf: str | Path | None = None) -> Recording:
    """Runs ``trace`` on the firmware ``elf`` (default: the bundled one, built if
    needed) in simavr and logs every event."""
    mega = VirtualMega(elf, millis_start=trace.millis_start)
    for t, data in trace.serial:
        mega.send(data, at=round(t * F_CPU))
    for side, train in trace.encoders.items():
        mega.encoder_edges(side, train)
    recorder = Recorder(mega)
    recorder.run_until(round(trace.duration * F_CPU))
    recording = recorder.recording(trace)
    mega.close()
    return recording


def initial_state(recording: Recording) -> FirmwareState:
    """The port's state after setup(): the default state with the boot millis()."""
    return FirmwareState(lastControlTime=int(recording.initial["lastControlTime"]))


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
    fw = Firmware(initial_state(recording))
    mismatches: list[Mismatch] = []
    fields_compared = 0
    # The state right after setup() must be the port's boot state.
    for name, port_value, fw_value in _differences(fw.state, recording.initial):
        mismatches.append(Mismatch(-1, 0, name, port_value, fw_value))
    boots = [bytearray(fw.boot_output())]           # the port's TX, boot by boot
    decoded = {side: _decoded_counts(recording.trace, side) for side in ("left", "right")}
    # What the decoder had counted when the firmware's counts started from 0 (at
    # setup(), somewhere between a reset and the first event after it): the candidates.
    offsets: dict[tuple[str, int], set[int]] = {(side, k): {0} for side in ("left", "right") for k in (0, 1)}
    resets = list(recording.resets)
    ticks = 0
    events = recording.events
    for i, ev in enumerate(events):
        tx = boots[-1]
        if ev.kind == "byte":
            tx += fw.feed(bytes([ev.arg]))
        else:
            ticks += 1
            latched = {name: int(ev.after[name])
                       for name in ("encTickL", "encTickR", "illTickL", "illTickR", "stormTickL",
                                    "stormTickR")}
            exit_cycle = events[i + 1].cycle if i + 1 < len(events) else recording.end_cycle
            for side, suffix in (("left", "L"), ("right", "R")):
                if latched["stormTick" + suffix]:
                    continue        # masked by the storm guard: its count stopped early
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
                          storm_l=latched["stormTickL"], storm_r=latched["stormTickR"])
        diffs = _differences(fw.state, ev.after)
        fields_compared += len(FLOAT_FIELDS) + len(INT_FIELDS) + 4
        for name, port_value, fw_value in diffs:
            mismatches.append(Mismatch(i, ticks, name, port_value, fw_value))
        port_io = ((fw.state.pwmL, fw.state.pwmR), (fw.state.dirL, fw.state.dirR))
        if port_io != (ev.pwm, ev.direction):
            mismatches.append(Mismatch(i, ticks, "pins (pwm, dir)", str(port_io),
                                       str((ev.pwm, ev.direction))))
        if int(ev.after.get("txDropped", 0)) != 0:
            mismatches.append(Mismatch(i, ticks, "txDropped", "0", str(ev.after["txDropped"])))
        next_cycle = events[i + 1].cycle if i + 1 < len(events) else recording.end_cycle
        while resets and resets[0][0] <= next_cycle:
            # The board reset before the next event: the port starts again from setup()
            # and must match the new boot's state.
            cycle, mcusr, booted = resets.pop(0)
            fw = Firmware(FirmwareState(lastControlTime=int(booted["lastControlTime"])))
            boots.append(bytearray(boot_line(reset_cause_name(mcusr))))
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
    return Report(len(events), ticks, fields_compared, mismatches, len(recording.tx))


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
