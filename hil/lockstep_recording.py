"""The stepping half of the lock-step proof: ``record(trace)`` runs a ``Trace`` on the
virtual Mega (``VirtualMega``) and gives its ``Recording``; ``Recorder`` does the
stepping for a run driven from outside (the scenario runner's simavr backend).

The Mega stops at the entry of every ``processByte``, ``controlTick`` and ``rxGap``
call. Each stop gives one firmware event (``Event``: the byte, the tick's ``millis()``,
or the count of bytes lost before the next) and the controller state the previous event
left, read from SRAM by symbol, with PWM and DIR from the I/O registers and the
EEPROM's contents. A reset (``Recorder.reset``) is logged with its MCUSR and the new
boot's state after ``setup()``. A trace's pokes (``Trace.pokes``) are written to SRAM at
the entry of the tick they fall before, and logged with its event.

The state an event leaves is read where the run next stops (the next event's entry, or
the end of a stretch of the run); so the last event is closed by running the Mega on
to the next event, or for ``FINISH_S`` at most, past the trace's end. An EEPROM-ready
interrupt (one byte of a ``save`` written) is logged by its cycle but is not an event:
it may come in the middle of one. What the port makes of a recording is
``wcdrive.hil.lockstep_comparison``'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from wcdrive.boards.current_sense import CURRENT_CHANNELS
from wcdrive.boards.simavr.mega_pins import INPUT_PINS
from wcdrive.boards.simavr.virtual_mega import F_CPU, RxLoss, VirtualMega
from wcdrive.boards.supply_sense import SUPPLY_CHANNEL
from wcdrive.firmware.state import FLOAT_FIELDS, INPUT_FIELDS, INT_FIELDS
from wcdrive.hil.traces import Trace

__all__ = ["FINISH_S", "Event", "Recorder", "Recording", "record"]

_WATCHED = FLOAT_FIELDS + INT_FIELDS + INPUT_FIELDS + ("rxLost",)

#: How long the Mega may run past the end of a trace to finish its last event (s).
FINISH_S = 0.02


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
    #: Globals the harness set at this tick's entry (``Trace.pokes``), before it ran.
    poke: dict[str, float | int] = field(default_factory=dict)


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


class Recorder:
    """Runs a ``VirtualMega`` and logs every firmware event with the state it leaves:
    ``run_until(cycle)`` stops at each ``processByte``/``controlTick`` entry, reads the
    controller globals, PWM and DIR, and goes on."""

    def __init__(self, mega: VirtualMega,
                 pokes: list[tuple[float, dict[str, float | int]]] | None = None) -> None:
        self.mega = mega
        #: (cycle, globals) to set at the entry of the first tick from that cycle on.
        self._pokes = sorted(((round(t * F_CPU), values) for t, values in pokes or ()), key=lambda p: p[0])
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
            while kind == "tick" and self._pokes and self._pokes[0][0] <= hit.cycle:
                for name, value in self._pokes.pop(0)[1].items():
                    mega.write(name, value)     # at the entry: the tick reads what was set
                    self.events[-1].poke[name] = mega.read(name)
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
        for t, number, active in trace.inhibits:
            mega.set_pin(INPUT_PINS[number], 0 if active else 1, at=round(t * F_CPU))
        for t, mv in trace.supply:
            mega.set_analog(SUPPLY_CHANNEL, mv, at=round(t * F_CPU))
        for t, side, mv in trace.currents:
            mega.set_analog(CURRENT_CHANNELS[side], mv, at=round(t * F_CPU))
        recorder = Recorder(mega, trace.pokes)
        for t, cause in sorted(trace.resets):
            recorder.run_until(round(t * F_CPU))
            recorder.reset(cause)
        recorder.run_until(round(trace.duration * F_CPU))
        return recorder.recording(trace)
    finally:
        mega.close()
