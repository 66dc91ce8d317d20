"""The closed loop: a scenario's host, the firmware (the port, or the ELF in simavr),
and the pymunk chair, at the firmware's own timing. ``run(scenario)`` runs one and
gives what it did, a ``SimResult`` (``wcdrive.sim.result``).

Time runs in 16 MHz cycles (``wcdrive.boards.port_loop``); the plant steps at a fixed
``dt`` (1 kHz by default) and sees the PWM/DIR of the last control tick. The host is
``wcdrive.sim.host.SimHost`` (the library's line decoder and odometry), steered in a
closed-loop run by ``wcdrive.sim.host.Pilot``.

This module sets a run up and sees it through: the plant, its gyro, the host, the
host's bytes on the wire (``wcdrive.sim.wire``) and the logs to fill
(``wcdrive.sim.run_logs``) make a ``Rig``; a ``Backend`` (``wcdrive.sim.backends``)
runs the firmware against it, ``PortBackend`` (``backend="port"``, the bit-exact
Python port) or ``SimavrBackend`` (``backend="simavr"``, the compiled firmware, its
events replayed on the port at the end: ``wcdrive.hil.lockstep``); and
``wcdrive.sim.result_assembly`` makes the ``SimResult`` of what the run left. Every
name of those modules that a caller used from here is still importable from here.

A scenario's ``[[fault]]`` entries act on both backends alike (``wcdrive.plant.faults``;
the boards inject the encoder, plant and reset faults, and the host's bytes that fall
in a ``link_cut`` never reach the board). The plant stands on the scenario's floor
(``[world]``, ``Scenario.terrain``) on both backends, and among its walls, from its
start pose (``Scenario.world``, ``Scenario.start``): the one plant both backends drive.
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.raycast import ScanPipe
from wcdrive.plant.world import World
from wcdrive.sim.backends import BACKENDS, Backend, BackendRun, PortBackend, Rig, SimavrBackend
from wcdrive.sim.host import Pilot, SimHost
from wcdrive.sim.result import STANDSTILL_SPEED, SimResult
from wcdrive.sim.result_assembly import assemble_result, fault_time, stop_time
from wcdrive.sim.run_logs import LineLog, TickLog
from wcdrive.sim.scanning import ScanRecorder
from wcdrive.sim.scenario import Scenario
from wcdrive.sim.wire import WireSchedule, wire_schedule

__all__ = ["STANDSTILL_SPEED", "Backend", "BackendRun", "LineLog", "PortBackend", "Rig", "SimResult",
           "SimavrBackend", "TickLog", "WireSchedule", "cyclic_gc_paused", "fault_time", "run",
           "stop_time", "wire_schedule"]


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
        # the port's loop as this module has it: a test or benchmark swaps ``PortLoop``
        # here for its stepped reference path
        chosen: Backend = PortBackend(PortLoop) if backend == "port" else SimavrBackend(elf)
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
                # closed loop: the parameters and the neutral command only (the pilot drives)
                if t < scenario.duration and not (closed and t >= scenario.host_offset_s + 0.02)]
    wire = wire_schedule(commands, scenario.faults)
    scanner, pipe = None, None
    if scenario.lidar is not None:        # no walls: every beam without a return
        pipe = ScanPipe.open()            # the turns made on a C thread (None: none to be had)
        scanner = ScanRecorder(scenario.lidar, scenario.world or World(), plant,
                               np.random.default_rng([seed, _LIDAR_STREAM]), pipe)
    rig = Rig(plant, gyro, host, pilot, TickLog(), LineLog(), wire, scenario.faults, dt,
              round(scenario.duration * F_CPU), progress, scanner, scenario.inhibits)
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
    return assemble_result(scenario, params, rig, ran, backend=chosen.name, wall=wall, commands=commands,
                           ekf=ekf)


#: The lidar noise's generator: ``default_rng([seed, _LIDAR_STREAM])``, apart from the gyro's.
_LIDAR_STREAM = 0x5CA9
