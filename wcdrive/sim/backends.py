"""The firmware in the loop: a ``Backend`` runs it from power-on against a ``Rig`` (the
plant and its gyro, the host and its pilot, the logs to fill, the host's bytes on the
wire) and says how the run ended (``BackendRun``).

* ``PortBackend`` (``backend="port"``): the bit-exact Python port (``PortLoop``).
* ``SimavrBackend`` (``backend="simavr"``): the compiled firmware, fed the plant's
  encoder edges at their exact times and the host's bytes at wire speed. Every firmware
  event is recorded, and at the end the port replays them (``wcdrive.hil.lockstep``) so
  the report gives the differences in the firmware outputs between the two (expected:
  none).

Both fill the rig alike (a ``TickLog`` row at every control tick; every byte the board
sends handed to the host and to the ``LineLog``), so that one assembly of the result
(``wcdrive.sim.result_assembly``) serves whichever backend ran.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wcdrive.boards.inhibits import LEVER_INPUT, InhibitChange
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.boards.simavr.mega_pins import INHIBIT_PINS
from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.hil.lockstep import Event, Recorder, compare
from wcdrive.hil.traces import Trace
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain
from wcdrive.plant.faults import Fault
from wcdrive.sim.host import Pilot, SimHost
from wcdrive.sim.result import Lockstep
from wcdrive.sim.run_logs import LineLog, TickLog
from wcdrive.sim.scanning import ScanRecorder
from wcdrive.sim.wire import WireSchedule

__all__ = ["BACKENDS", "Backend", "BackendRun", "PortBackend", "Rig", "SimavrBackend"]


def _board_values(a: dict[str, float | int]) -> tuple[tuple[float, float], tuple[float, float],
                                                     tuple[int, int], tuple[int, int]]:
    """A tick's (setpoints, filtered speeds, signed duties, counts) from the firmware's
    globals ``a``."""
    return ((float(a["setpointL"]), float(a["setpointR"])), (float(a["filtVelL"]), float(a["filtVelR"])),
            (_signed(int(a["pwmL"]), int(a["dirL"])), _signed(int(a["pwmR"]), int(a["dirR"]))),
            (int(a["encTickL"]), int(a["encTickR"])))


def _signed(pwm: int, direction: int) -> int:
    return pwm if direction else -pwm


@dataclass
class Rig:
    """What a ``Backend`` runs the firmware against: the plant (its motion log on) and
    its gyro, the host and, in closed loop, its pilot, the tick and line logs to fill,
    the host's bytes on the wire, the scenario's faults, the physics step ``dt`` (s), the
    cycle the run ends at, and ``progress`` (``run``'s)."""

    plant: Plant
    gyro: Gyro
    host: SimHost
    pilot: Pilot | None
    log: TickLog
    lines: LineLog
    wire: WireSchedule
    faults: tuple[Fault, ...]
    dt: float
    end_cycle: int
    progress: Callable[[float], None] | None = None
    #: The lidar's scans (``wcdrive.sim.scanning``): polled after every tick or step.
    scanner: ScanRecorder | None = None
    #: The inhibit inputs' timeline (the scenario's ``[[input]]`` tables).
    inhibits: tuple[InhibitChange, ...] = ()


@dataclass(frozen=True)
class BackendRun:
    """How a backend's run ended: the cycle it stopped at (a closed-loop run stops once
    its pilot is done) and, for the compiled firmware, its comparison with the port."""

    end_cycle: int
    lockstep: Lockstep | None = None


class Backend(Protocol):
    """Runs the firmware in the loop: ``PortBackend`` or ``SimavrBackend``."""

    name: str

    def run(self, rig: Rig) -> BackendRun:
        """Runs the firmware from power-on against ``rig`` to ``rig.end_cycle`` (in
        closed loop, until ``rig.pilot`` is done): sends the wire's bytes (and the
        pilot's commands) at their cycles, hands every byte the board sends to
        ``rig.host`` and ``rig.lines``, and adds a ``rig.log`` row at every control
        tick."""
        ...


class PortBackend:
    """The bit-exact Python port, in ``PortLoop``, or in what ``loop`` makes from the
    same arguments (``PortLoop`` on its stepped reference path, say)."""

    name = "port"

    def __init__(self, loop: Callable[..., PortLoop] = PortLoop) -> None:
        self.loop = loop

    def run(self, rig: Rig) -> BackendRun:
        """``Backend.run``."""
        plant, host, log, lines, pilot = rig.plant, rig.host, rig.log, rig.lines, rig.pilot
        end_cycle, progress = rig.end_cycle, rig.progress
        loop = self.loop(plant, rig.gyro, rig.dt, faults=rig.faults, inhibits=rig.inhibits)
        for cycle, data in rig.wire.runs:
            loop.send(data, at=cycle)
        last_progress = [0.0]
        poll = rig.scanner.poll if rig.scanner is not None else None

        def take() -> None:
            for cycle, out in loop.take_output():
                host.receive(cycle / F_CPU, out)
                lines.feed(cycle, out)

        def on_tick(t: float) -> None:
            take()
            s = loop.fw.state
            assert loop.last_tick_cycle is not None
            log.add(loop.last_tick_cycle, plant, host, (s.setpointL, s.setpointR), (s.filtVelL, s.filtVelR),
                    (_signed(s.pwmL, s.dirL), _signed(s.pwmR, s.dirR)), (s.encTickL, s.encTickR))
            if poll is not None:
                poll()
            if progress and t - last_progress[0] > 1.0:
                progress(t * F_CPU / end_cycle)
                last_progress[0] = t

        if pilot is None:
            loop.run_until(end_cycle, on_tick)
            take()
            return BackendRun(end_cycle)
        while pilot.next < end_cycle and not pilot.finished():
            loop.run_until(pilot.next, on_tick)
            take()
            cycle, data = pilot.step()
            loop.send(data, at=cycle)
        end = min(pilot.next, end_cycle)
        loop.run_until(end, on_tick)
        take()
        return BackendRun(end)


class SimavrBackend:
    """The compiled firmware ``elf`` (by default the bundled one, built if needed) in
    simavr (``VirtualMega``), the plant on its pins; its events replayed on the port at
    the end (``BackendRun.lockstep``)."""

    name = "simavr"

    def __init__(self, elf=None) -> None:
        self.elf = elf

    def run(self, rig: Rig) -> BackendRun:
        """``Backend.run``."""
        plant, host, log, lines, pilot = rig.plant, rig.host, rig.log, rig.lines, rig.pilot
        dt, end_cycle, progress = rig.dt, rig.end_cycle, rig.progress
        step_cycles = round(dt * F_CPU)
        mega = VirtualMega(self.elf)
        recorder = Recorder(mega)
        levers = [(c.cycle(F_CPU), c.active) for c in rig.inhibits if c.number == LEVER_INPUT]
        pins = PlantOnPins(mega, plant, rig.gyro, faults=rig.faults, levers=levers)
        for change in rig.inhibits:       # active LOW: the pin pulled to ground
            if change.number != LEVER_INPUT:    # the lever's switch: the plant's (PlantOnPins)
                mega.set_pin(INHIBIT_PINS[change.number], 0 if change.active else 1, at=change.cycle(F_CPU))
        trains: dict[str, list[EdgeTrain]] = {"left": [], "right": []}
        tx_seen = 0
        n_events_logged = 0
        open_tick: tuple[int, Event] | None = None
        runs = rig.wire.runs
        poll = rig.scanner.poll if rig.scanner is not None else None
        next_run = 0
        steps = end_cycle // step_cycles
        piloted: list[tuple[int, bytes]] = []
        for k in range(steps):
            t0, t1 = k * dt, (k + 1) * dt
            if pilot is not None:
                if pilot.finished():
                    end_cycle = k * step_cycles
                    break
                while pilot.next < (k + 1) * step_cycles:
                    cycle, data = pilot.step()
                    mega.send(data, at=cycle)
                    piloted.append((cycle, data))
            # The host's bytes are queued a step ahead, so that the harness's queue stays
            # short (an encoder storm queues millions of edges).
            while next_run < len(runs) and runs[next_run][0] < (k + 1) * step_cycles:
                mega.send(runs[next_run][1], at=runs[next_run][0])
                next_run += 1
            for side, train in pins.step(t0, t1, recorder.run_until, recorder.reset).items():
                if train.times.size:
                    trains[side].append(train)
            if poll is not None:
                poll()
            if len(mega.tx_log) > tx_seen:
                fresh = mega.tx_log[tx_seen:]
                host.receive(t1, bytes(b for _, b in fresh))
                lines.feed_stamped(fresh)
                tx_seen = len(mega.tx_log)
            # A step can end inside a tick: its row's firmware columns are read again
            # until a later event shows the tick has ended.
            if open_tick is not None:
                log.board(open_tick[0], *_board_values(open_tick[1].after))
                if open_tick[1] is not recorder.events[-1]:
                    open_tick = None
            for ev in recorder.events[n_events_logged:]:
                if ev.kind == "tick" and ev.after:
                    log.add(ev.cycle, plant, host, *_board_values(ev.after))
                    if ev is recorder.events[-1]:
                        open_tick = (len(log.tick_cycles) - 1, ev)
            n_events_logged = len(recorder.events)
            if progress and k % 1000 == 0:
                progress(k / steps)
        encoders = {}
        for side, parts in trains.items():
            if parts:
                encoders[side] = EdgeTrain(np.concatenate([p.times for p in parts]),
                                           np.concatenate([p.states for p in parts]), 0, 0)
        trace = Trace(duration=end_cycle / F_CPU, serial=[(c / F_CPU, d) for c, d in sorted(runs + piloted)],
                      encoders=encoders,
                      inhibits=sorted([(c.at, c.number, c.active) for c in rig.inhibits
                                       if c.number != LEVER_INPUT] + pins.input_changes),
                      supply=list(pins.supply_changes), currents=list(pins.current_changes))
        report = compare(recorder.recording(trace))
        mega.close()
        return BackendRun(end_cycle, Lockstep(len(report.mismatches), report.events))


BACKENDS = ("port", "simavr")
