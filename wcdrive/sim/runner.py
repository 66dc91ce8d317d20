"""The closed loop: a scenario's host, the firmware (the port, or the ELF in simavr),
and the pymunk chair, at the firmware's own timing.

Time runs in 16 MHz cycles (``wcdrive.boards.port_loop``); the plant steps at a fixed
``dt`` (1 kHz by default) and sees the PWM/DIR of the last control tick. The host is
``wcdrive.sim.host.SimHost`` (the library's line decoder and odometry), steered in a
closed-loop run by ``wcdrive.sim.host.Pilot``.

A ``Backend`` runs the firmware against a ``Rig`` (the plant, its gyro, the host, the
logs, the host's bytes on the wire):

* ``PortBackend`` (``backend="port"``): the bit-exact Python port (``PortLoop``).
* ``SimavrBackend`` (``backend="simavr"``): the compiled firmware, fed the plant's
  encoder edges at their exact times and the host's bytes at wire speed. Every firmware
  event is recorded, and at the end the port replays them (``wcdrive.hil.lockstep``) so
  the report gives the differences in the firmware outputs between the two (expected:
  none).

A scenario's ``[[fault]]`` entries act on both backends alike (``wcdrive.plant.faults``;
the boards inject the encoder, plant and reset faults, and the host's bytes that fall
in a ``link_cut`` never reach the board). The plant stands on the scenario's floor
(``[world]``, ``Scenario.terrain``) on both backends, and among its walls, from its
start pose (``Scenario.world``, ``Scenario.start``): the one plant both backends drive.
What a run gives is a ``SimResult`` (``wcdrive.sim.result``).
"""

from __future__ import annotations

import gc
import math
import re
import threading
import time
from array import array
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.hil.lockstep import Event, Recorder, compare
from wcdrive.hil.traces import Trace
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain
from wcdrive.plant.faults import Fault
from wcdrive.plant.raycast import ScanPipe
from wcdrive.plant.world import World
from wcdrive.sim.host import Pilot, SimHost
from wcdrive.sim.result import (
    STANDSTILL_SPEED,
    BoardLog,
    Goal,
    GroundTruth,
    LidarLog,
    LinkLog,
    Lockstep,
    Odometry,
    SimResult,
    WorldLog,
)
from wcdrive.sim.scanning import ScanRecorder
from wcdrive.sim.scenario import Scenario, Segment

__all__ = ["STANDSTILL_SPEED", "Backend", "BackendRun", "LineLog", "PortBackend", "Rig", "SimResult",
           "SimavrBackend", "TickLog", "WireSchedule", "cyclic_gc_paused", "fault_time", "run",
           "stop_time", "wire_schedule"]


#: The tick log's columns and their widths, in the order ``TickLog.add`` writes them.
_LOG_COLUMNS = (("tick_time", 1), ("truth", 3), ("odom_wheel", 3), ("odom_velocity", 3), ("odom_gyro", 3),
                ("setpoint", 2), ("measured", 2), ("wheel_speed", 2), ("pwm", 2), ("caster", 2),
                ("counts", 2), ("odom_ekf", 3), ("odom_ekf_vel", 3))
_LOG_WIDTH = sum(width for _, width in _LOG_COLUMNS)
#: Where each column starts in a row.
_LOG_OFFSETS = {name: sum(w for _, w in _LOG_COLUMNS[:i]) for i, (name, _) in enumerate(_LOG_COLUMNS)}


class TickLog:
    """A row of numbers per control tick, kept flat in one ``array('d')``: no object
    per row outlives the tick, so the run leaves the garbage collector (paused for
    the run, ``cyclic_gc_paused``) nothing to scan when it comes back on."""

    def __init__(self) -> None:
        self._flat = array("d")
        self.tick_cycles: list[int] = []

    def add(self, cycle: int, plant: Plant, host: SimHost, setpoint, measured, pwm, counts) -> None:
        """The row of the control tick at ``cycle``: the plant's state now, the host's
        estimates, and the tick's setpoints, filtered speeds, signed duties and counts
        (each a (left, right) pair)."""
        wheel, velocity, gyro, ekf, ekf_vel = host.poses()
        speed = plant.s.speed
        # the casters' world headings; ``arrays`` makes them relative to the chassis
        caster = plant.caster_heading
        self._flat.extend((cycle / F_CPU, *plant.pose, *wheel, *velocity, *gyro, setpoint[0], setpoint[1],
                           measured[0], measured[1], speed[0], speed[1], pwm[0], pwm[1], caster[0], caster[1],
                           counts[0], counts[1], *ekf, *ekf_vel))
        self.tick_cycles.append(cycle)

    def board(self, row: int, setpoint, measured, pwm, counts) -> None:
        """Rewrites the firmware's columns of ``row`` (the plant's and host's stay as
        ``add`` took them): for a tick whose state was read before the tick had ended."""
        at = row * _LOG_WIDTH
        for name, pair in (("setpoint", setpoint), ("measured", measured), ("pwm", pwm), ("counts", counts)):
            start = at + _LOG_OFFSETS[name]
            self._flat[start:start + 2] = array("d", pair)

    def arrays(self) -> dict[str, np.ndarray]:
        """The columns (``_LOG_COLUMNS``) as arrays, a row per tick (one row of zeros
        without a tick), the casters relative to the chassis, and ``tick_cycles``."""
        names = [name for name, _ in _LOG_COLUMNS]
        out: dict[str, np.ndarray]
        if not self.tick_cycles:
            z3, z2 = np.zeros((1, 3)), np.zeros((1, 2))
            out = {n: z2 for n in names}
            out.update(tick_time=np.zeros(1), truth=z3, odom_wheel=z3, odom_velocity=z3, odom_gyro=z3,
                       odom_ekf=z3, odom_ekf_vel=z3)
        else:
            table = np.frombuffer(self._flat, dtype=np.float64).reshape(len(self.tick_cycles), _LOG_WIDTH)
            out, at = {}, 0
            for name, width in _LOG_COLUMNS:
                out[name] = np.array(table[:, at] if width == 1 else table[:, at:at + width])
                at += width
            # _wrap(heading - chassis heading), the same operations element by element
            relative = out["caster"] - out["truth"][:, 2:3]
            out["caster"] = (relative + math.pi) % (2 * math.pi) - math.pi
        out["tick_cycles"] = np.array(self.tick_cycles, dtype=np.int64)
        return out


class LineLog:
    """The board's TX stream cut into lines, each stamped with the cycle of its last
    byte; keeps the ``EVT:`` and ``BOOT:`` lines."""

    def __init__(self) -> None:
        self._partial = bytearray()
        self.events: list[tuple[float, str]] = []
        self.boots: list[tuple[float, str]] = []
        # every line's time and text, apart: no object per line for the collector (``TickLog``)
        self._times = array("d")
        self._texts: list[str] = []

    @property
    def all(self) -> list[tuple[float, str]]:
        """Every line as (s, text)."""
        return list(zip(self._times, self._texts, strict=True))

    def feed(self, cycle: int, data: bytes) -> None:
        """The board's bytes ``data``, the last one sent at ``cycle``."""
        self._partial += data
        if b"\n" not in data:
            return
        *lines, rest = self._partial.split(b"\n")
        self._partial = rest
        t = cycle / F_CPU
        for raw in lines:
            line = raw.rstrip(b"\r").decode("latin-1")
            self._times.append(t)
            self._texts.append(line)
            if line.startswith("EVT:"):
                self.events.append((round(t, 6), line))
            elif line.startswith("BOOT:"):
                self.boots.append((round(t, 6), line))

    def feed_stamped(self, stamped: list[tuple[int, int]]) -> None:
        """(cycle, byte) pairs, as the simulated Mega logs its TX."""
        start = 0
        for i, (cycle, byte) in enumerate(stamped):
            if byte == 0x0A:
                self.feed(cycle, bytes(b for _, b in stamped[start:i + 1]))
                start = i + 1
        if start < len(stamped):
            self._partial += bytes(b for _, b in stamped[start:])


def _board_values(a: dict[str, float | int]) -> tuple[tuple[float, float], tuple[float, float],
                                                     tuple[int, int], tuple[int, int]]:
    """A tick's (setpoints, filtered speeds, signed duties, counts) from the firmware's
    globals ``a``."""
    return ((float(a["setpointL"]), float(a["setpointR"])), (float(a["filtVelL"]), float(a["filtVelR"])),
            (_signed(int(a["pwmL"]), int(a["dirL"])), _signed(int(a["pwmR"]), int(a["dirR"]))),
            (int(a["encTickL"]), int(a["encTickR"])))


def _signed(pwm: int, direction: int) -> int:
    return pwm if direction else -pwm


@dataclass(frozen=True)
class WireSchedule:
    """The host's bytes on the wire: ``runs`` of bytes that reach the board, each
    (start cycle, bytes), one byte every ``UART_BYTE_CYCLES``; ``received`` the cycle at
    which each delivered byte has fully arrived, and ``sent`` the start cycle of every
    byte the host sent (delivered or not)."""

    runs: list[tuple[int, bytes]]
    received: np.ndarray
    received_start: np.ndarray


def wire_schedule(commands: list[tuple[int, bytes]], faults: tuple[Fault, ...] = ()) -> WireSchedule:
    """Lays the host's commands ((cycle, bytes), in order) on the wire as both boards do
    (a command starts when it is sent or when the previous one has gone) and drops the
    bytes whose transmission starts while a ``link_cut`` acts."""
    cuts = [f.cycles(F_CPU) for f in faults if f.kind == "link_cut"]
    runs: list[tuple[int, bytes]] = []
    received: list[int] = []
    starts: list[int] = []
    free = 0
    for cycle, data in commands:
        start = max(cycle, free)
        free = start + len(data) * UART_BYTE_CYCLES
        run_start, run = 0, bytearray()
        for i, byte in enumerate(data):
            at = start + i * UART_BYTE_CYCLES
            lost = any(lo <= at and (hi is None or at < hi) for lo, hi in cuts)
            if lost:
                if run:
                    runs.append((run_start, bytes(run)))
                    run = bytearray()
                continue
            if not run:
                run_start = at
            run.append(byte)
            starts.append(at)
            received.append(at + UART_BYTE_CYCLES)
        if run:
            runs.append((run_start, bytes(run)))
    return WireSchedule(runs, np.array(received, dtype=np.int64), np.array(starts, dtype=np.int64))


def fault_time(scenario: Scenario, wire: WireSchedule) -> float | None:
    """When the fault figures count from (``SimResult.fault_metrics``): the earliest of
    the faults' ``at`` and of the ``silence`` segments' starts; for a ``link_cut`` or a
    silence, the time at which the last byte that started before it reached the board.
    None when the scenario has neither."""
    triggers: list[tuple[float, bool]] = [(f.at, f.kind == "link_cut") for f in scenario.faults]
    t0 = 0.02
    for seg in scenario.segments:
        if seg.kind == "silence":
            triggers.append((t0, True))
            break
        t0 += seg.duration
    if not triggers:
        return None
    at, by_last_byte = min(triggers)
    return _last_byte_before(wire, at) if by_last_byte else at


def stop_time(scenario: Scenario, wire: WireSchedule, events: list[tuple[float, str]],
              done_at: float | None = None) -> float | None:
    """When the stop figures count from (``SimResult.stop_metrics``): the start of the
    run's last stop, the earliest of

    * in open loop, the start of the stretch of segments at the end that command no
      motion (``stop`` and ``silence`` segments, a ``cmdvel`` or ``wheel`` of zeros, and
      the stop the host sends after the last segment): its first segment's start, or,
      for a ``silence``, the time the last byte before it reached the board (as for
      the fault figures, ``fault_time``); 0 when no segment commands motion (the chair
      is parked from the start); in closed loop, ``done_at`` (s), when the pilot
      reached its goal and stopped;
    * a ``link_cut`` that lasts past the last segment: the last byte before it;
    * the board's first ``EVT:FAULT`` line (a latched fault refuses motion until
      reset): from the latest fault at or before it (a ``link_cut``'s from the last byte
      before it), or from the line itself when the fault was none of the scenario's.

    None when there is none before the run's end (``scenario.duration``)."""
    candidates: list[float] = []
    if scenario.closed_loop:
        if done_at is not None:
            candidates.append(done_at)
    else:
        t0 = 0.02
        start: float | None = 0.0
        for seg in scenario.segments:
            if _commands_motion(seg):
                start = None
            elif start is None:
                start = _last_byte_before(wire, t0) if seg.kind == "silence" else t0
            t0 += seg.duration
        candidates.append(t0 if start is None else start)
    end_of_segments = 0.02 + sum(seg.duration for seg in scenario.segments)
    for f in scenario.faults:
        if f.kind == "link_cut" and (f.duration is None or f.at + f.duration >= end_of_segments):
            candidates.append(_last_byte_before(wire, f.at))
    latched = [t for t, line in events if line.startswith("EVT:FAULT,")]
    if latched:
        before = [f for f in scenario.faults if f.at <= latched[0] + 1e-9]
        if not before:
            candidates.append(latched[0])
        else:
            fault = max(before, key=lambda f: f.at)
            candidates.append(_last_byte_before(wire, fault.at) if fault.kind == "link_cut" else fault.at)
    at = min(candidates, default=None)
    return at if at is not None and at < scenario.duration else None


def _commands_motion(seg: Segment) -> bool:
    """Whether the segment asks the chair to move (a ``cmdvel`` or ``wheel`` of zeros
    does not; a PPM frame is taken to)."""
    if seg.kind in ("stop", "silence"):
        return False
    return seg.kind == "ppm" or any(v != 0.0 for v in seg.values)


def _last_byte_before(wire: WireSchedule, at: float) -> float:
    """s: when the last byte whose transmission started before ``at`` reached the
    board (0 if none did)."""
    before = np.flatnonzero(wire.received_start < round(at * F_CPU))
    return float(wire.received[before[-1]]) / F_CPU if before.size else 0.0


@contextmanager
def cyclic_gc_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off for a run, back on (if it was) after.

    A run allocates some containers a tick that live on (the tick log's rows, the
    gyro's samples), so the collector's generational passes keep re-scanning a growing
    heap: a quarter of ``corridor_100m``'s time in a process that has imported
    ``wcdrive.tools.cli``. A run makes no cyclic garbage a tick (reference counting frees
    what it drops; the few objects a run leaves in cycles are the same whatever its
    length: tests/sim/test_sim_speed.py), so nothing piles up while the collector waits.

    Runs in several threads at once (a Dask worker's) share the pause: the collector
    comes back when the last of them ends, if it was on when the first began."""
    global _paused_runs, _gc_was_enabled
    with _gc_pause_lock:
        if _paused_runs == 0:
            _gc_was_enabled = gc.isenabled()
            gc.disable()
        _paused_runs += 1
    try:
        yield
    finally:
        with _gc_pause_lock:
            _paused_runs -= 1
            if _paused_runs == 0 and _gc_was_enabled:
                gc.enable()


_gc_pause_lock = threading.Lock()
_paused_runs = 0
_gc_was_enabled = False


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
    """The bit-exact Python port, in ``PortLoop``."""

    name = "port"

    def run(self, rig: Rig) -> BackendRun:
        """``Backend.run``."""
        plant, host, log, lines, pilot = rig.plant, rig.host, rig.log, rig.lines, rig.pilot
        end_cycle, progress = rig.end_cycle, rig.progress
        loop = PortLoop(plant, rig.gyro, rig.dt, faults=rig.faults)
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
        pins = PlantOnPins(mega, plant, rig.gyro, faults=rig.faults)
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
                      encoders=encoders)
        report = compare(recorder.recording(trace))
        mega.close()
        return BackendRun(end_cycle, Lockstep(len(report.mismatches), report.events))


BACKENDS = ("port", "simavr")


def run(scenario: Scenario, *, backend: str | Backend = "port", seed: int = 0, dt: float = 0.001,
        progress: Callable[[float], None] | None = None, elf=None, ekf: bool = False) -> SimResult:
    """Runs ``scenario`` in closed loop: ``backend`` "port" (the Python port), "simavr"
    (the ELF ``elf``, by default the bundled firmware, built if needed) or a ``Backend``,
    the plant stepping every ``dt`` s, with the scenario's faults. ``seed`` seeds the
    gyro and the lidar's range noise (a scenario with a ``[lidar]``: its scans in
    ``SimResult.lidar``); ``progress`` is called now and then with the fraction done;
    ``ekf`` runs the seeds' EKFs (``Odometry.ekf``, ``Odometry.ekf_vel``) on the host too."""
    if isinstance(backend, str):
        if backend not in BACKENDS:
            raise ValueError("backend must be 'port' or 'simavr'")
        chosen: Backend = PortBackend() if backend == "port" else SimavrBackend(elf)
    else:
        chosen = backend
    if not 1e-5 <= dt <= 0.01:
        raise ValueError("dt must be within 10 us .. 10 ms")
    params = scenario.params()
    x0, y0, heading0 = scenario.start
    plant = Plant(params, x=x0, y=y0, heading=heading0, terrain=scenario.terrain, world=scenario.world)
    plant.start_motion_log()
    gyro = Gyro(params, seed)
    closed = scenario.closed_loop
    host = SimHost(params, gyro, ekf or (closed and scenario.follow.localization == "ekf"))
    pilot = Pilot(scenario, host) if closed else None
    commands = [(round(t * F_CPU), data) for t, data in scenario.host_commands()
                if t < scenario.duration and not (closed and t >= 0.02)]   # closed: params only
    wire = wire_schedule(commands, scenario.faults)
    scanner, pipe = None, None
    if scenario.lidar is not None:        # no walls: every beam without a return
        pipe = ScanPipe.open()            # the turns made on a C thread (None: none to be had)
        scanner = ScanRecorder(scenario.lidar, scenario.world or World(), plant,
                               np.random.default_rng([seed, _LIDAR_STREAM]), pipe)
    rig = Rig(plant, gyro, host, pilot, TickLog(), LineLog(), wire, scenario.faults, dt,
              round(scenario.duration * F_CPU), progress, scanner)
    wall0 = time.perf_counter()
    try:
        with cyclic_gc_paused():
            ran = chosen.run(rig)
            if scanner is not None:
                scanner.poll()                # a turn that ended with the run's last step
                scanner.finish()
    finally:
        if pipe is not None:
            pipe.close()
    wall = time.perf_counter() - wall0
    goal = None
    if pilot is not None:
        commands += pilot.sent
        goal = Goal(pilot.ctl.goal, None if pilot.done_at is None else pilot.done_at / F_CPU,
                    scenario.follow.truth_tolerance, scenario.follow.localization)
    motion = plant.take_motion_log()
    if scanner is not None:
        motion = np.concatenate([*scanner.motion(), motion])
    half = 0.5 * params.wheelbase
    contact = np.stack((np.hypot(motion[:, 1] - motion[:, 3] * half, motion[:, 2]),
                        np.hypot(motion[:, 1] + motion[:, 3] * half, motion[:, 2])), axis=1)
    cols = rig.log.arrays()
    truth = GroundTruth(cols["truth"], cols["wheel_speed"], cols["caster"], plant.caster_scrub_energy,
                        plant.caster_scrub_time, plant.caster_swivel_work, plant.caster_side_impulse,
                        step_time=motion[:, 0],
                        step_speed=contact.max(axis=1) if contact.size else np.zeros(0),
                        step_contact_speed=contact, step_volts=motion[:, 4:6])
    board = BoardLog(cols["tick_time"], cols["setpoint"], cols["measured"], cols["pwm"], cols["counts"],
                     cols["tick_cycles"])
    odometry = Odometry(cols["odom_wheel"], cols["odom_velocity"], cols["odom_gyro"],
                        cols["odom_ekf"] if ekf else None, cols["odom_ekf_vel"] if ekf else None,
                        gyro_time=np.array(gyro.times), gyro_rate=np.array(gyro.rates))
    lines = rig.lines
    link = LinkLog(lines.all, lines.events, lines.boots, dict(host.line_counts), _cmd_vel(commands))
    stop_at = stop_time(scenario, wire, lines.events, None if goal is None else goal.reached_s)
    return SimResult(scenario=scenario.name, backend=chosen.name, duration=ran.end_cycle / F_CPU,
                     wall_time=wall, truth=truth, board=board, odometry=odometry, link=link,
                     faults=scenario.faults, fault_at=fault_time(scenario, wire), goal=goal,
                     lockstep=ran.lockstep, stop_at=stop_at, terrain=scenario.terrain,
                     world=_world_log(scenario, plant),
                     lidar=None if scanner is None else LidarLog(scanner.lidar, scanner.scans))


#: The lidar noise's generator: ``default_rng([seed, _LIDAR_STREAM])``, apart from the gyro's.
_LIDAR_STREAM = 0x5CA9


def _world_log(scenario: Scenario, plant: Plant) -> WorldLog | None:
    """The start pose and the plant's collisions (None for a scenario with neither walls
    nor a start pose of its own)."""
    world = scenario.world
    if world is None and scenario.start == (0.0, 0.0, 0.0):
        return None
    if world is None:
        return WorldLog(scenario.start)
    contacts = plant.contacts
    return WorldLog(scenario.start, world.segments.copy(), world.circles.copy(), contacts.count,
                    contacts.first_time, contacts.max_impact, contacts.contact_time, contacts.records(),
                    world.grid)


def _cmd_vel(commands: list[tuple[int, bytes]]) -> list[tuple[float, float, float]]:
    """The host's motion commands as (s, m/s, rad/s): ``x:``/``t:`` as sent, wheel
    commands (``r``/``l`` rad/s) through the chair's kinematics (other commands: none)."""
    from wcdrive.protocol.spec import real

    radius, base = real("WHEEL_RADIUS"), real("WHEELBASE")
    out = []
    for cycle, data in commands:
        text = data.decode("latin-1")
        if m := _CMDVEL.fullmatch(text.strip()):
            out.append((cycle / F_CPU, float(m[1]), float(m[2])))
        elif m := _WHEEL.fullmatch(text.strip()):
            r = float(m[2]) * (-1 if m[1] == "n" else 1)
            lft = float(m[4]) * (-1 if m[3] == "n" else 1)
            out.append((cycle / F_CPU, 0.5 * radius * (r + lft), radius * (r - lft) / base))
    return out


_CMDVEL = re.compile(r"x:(-?[\d.]+),t:(-?[\d.]+),")
_WHEEL = re.compile(r"r([pn])([\d.]+),l([pn])([\d.]+),")
