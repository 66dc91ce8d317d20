"""The closed loop: a scenario's host, the firmware (the port, or the ELF in simavr),
and the pymunk chair, at the firmware's own timing.

Time runs in 16 MHz cycles (``wcdrive.boards.port_loop``); the plant steps at a fixed
``dt`` (1 kHz by default) and sees the PWM/DIR of the last control tick.

* ``backend="port"``: the bit-exact Python port (``PortLoop``).
* ``backend="simavr"``: the compiled firmware, fed the plant's encoder edges at
  their exact times and the host's bytes at wire speed. Every firmware event is
  recorded, and at the end the port replays them (``wcdrive.hil.lockstep``) so the report
  gives the differences in the firmware outputs between the two (expected: none).

A scenario's ``[[fault]]`` entries act on both backends alike (``wcdrive.plant.faults``;
the boards inject the encoder, plant and reset faults, and the host's bytes that fall
in a ``link_cut`` never reach the board). The ground truth of the fault figures
(``fault_metrics``) is the plant's motion after every physics step: the chair's speed is
that of the faster of its two drive-wheel contact points (so a chair spinning on the
spot is not "still"), and its travel the longer of their two paths.
"""

from __future__ import annotations

import bisect
import gc
import math
import re
import threading
import time
from array import array
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.hil.lockstep import Recorder, compare
from wcdrive.hil.traces import Trace
from wcdrive.host.odometry import GyroIntegrator, OdometryParams, WheelOdometry
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain
from wcdrive.plant.faults import Fault
from wcdrive.protocol.codec import Feedback, LineDecoder, encode_cmdvel
from wcdrive.sim.localization import Ekf2D, EkfConfig
from wcdrive.sim.navigation import PurePursuit
from wcdrive.sim.scenario import Scenario

#: m/s: the chair is at a standstill once its speed stays below this.
STANDSTILL_SPEED = 0.01


@dataclass
class SimResult:
    """One run of a scenario: arrays with a row per control tick (columns as noted),
    the plant's caster totals, the board's line counts and, with the simavr backend,
    the comparison of the firmware with the port."""

    scenario: str
    backend: str
    duration: float
    wall_time: float
    ticks: int
    tick_time: np.ndarray
    truth: np.ndarray           # (n, 3): x, y, heading at each tick
    odom_wheel: np.ndarray      # (n, 3): position-based wheel odometry (host side)
    odom_velocity: np.ndarray   # (n, 3): velocity-based
    odom_gyro: np.ndarray       # (n, 3): wheel distance + gyro heading
    setpoint: np.ndarray        # (n, 2): left, right ramped setpoints (rad/s)
    measured: np.ndarray        # (n, 2): filtered wheel speed the PID saw
    wheel_speed: np.ndarray     # (n, 2): true wheel speed
    pwm: np.ndarray             # (n, 2): signed duty (-255..255)
    caster: np.ndarray          # (n, 2): caster swivel angles relative to the chassis (rad)
    counts: np.ndarray          # (n, 2): the encoder counts the tick latched (left, right)
    caster_scrub_energy: float
    caster_scrub_time: float
    caster_swivel_work: float
    caster_side_impulse: float
    firmware_differences: int | None = None
    firmware_events_compared: int | None = None
    lines: dict[str, int] = field(default_factory=dict)
    #: Per physics step: the time at its end (s), the chair's speed (m/s, module
    #: docstring), the wheels' contact speeds (left, right; m/s) and the motor
    #: voltages the driver applied over it (left, right; V, signed).
    step_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    step_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    step_contact_speed: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    step_volts: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    #: The cycle of every control tick.
    tick_cycles: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: Every ``EVT:`` line and every ``BOOT:`` line the board sent, as (s, line).
    events: list[tuple[float, str]] = field(default_factory=list)
    boots: list[tuple[float, str]] = field(default_factory=list)
    faults: tuple[Fault, ...] = ()
    #: ``fault_metrics``: when the fault figures count from (None: no fault, no silence).
    fault_at: float | None = None
    #: (n, 3): the seeds' EKF (``wcdrive.sim.localization``) on velocity odometry and the
    #: gyro: seed 000's ekf.yaml (wheels: x, y, vx), and seed 002's scheme (wheels: vx, vy).
    #: None unless the run asked for them (``run(..., ekf=True)``).
    odom_ekf: np.ndarray | None = None
    odom_ekf_vel: np.ndarray | None = None
    #: The gyro's samples (s, rad/s), every line the board sent (s, line) and the
    #: host's velocity commands (s, m/s, rad/s): what ``wcdrive sim --mcap`` records.
    gyro_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gyro_rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    serial_lines: list[tuple[float, str]] = field(default_factory=list)
    cmd_vel: list[tuple[float, float, float]] = field(default_factory=list)
    #: A closed-loop run (a ``path`` scenario): the goal (m), the time the host's
    #: estimate reached it (None: never), the published bound on the true error (m) and
    #: which estimate the host steered by.
    goal: tuple[float, float] | None = None
    goal_reached_s: float | None = None
    goal_tolerance: float | None = None
    steered_by: str | None = None

    def fault_metrics(self) -> dict[str, float | None]:
        """The fault figures: ``max_tick_gap_ms`` (the longest interval between two
        control ticks, or from the last tick to the end, by the simulated clock),
        ``fault_at_s`` (the first fault's ``at``; for a ``link_cut`` or a ``silence``
        segment, the time the last byte before it reached the board), and from then
        on: ``pwm_zero_after_fault_s`` (until both duties are 0 to the end),
        ``standstill_after_fault_s`` (until the chair's speed stays below
        ``STANDSTILL_SPEED``), ``travel_after_fault_m`` and
        ``peak_speed_after_fault_mps``; None where there is no fault or it never
        happens."""
        ticks = self.tick_cycles
        end = round(self.duration * F_CPU)
        if ticks.size:
            gaps = np.diff(np.concatenate((ticks, [end])))
            gap = float(gaps.max()) / F_CPU * 1000.0
        else:
            gap = self.duration * 1000.0
        out: dict[str, float | None] = {"max_tick_gap_ms": gap, "fault_at_s": self.fault_at,
                                        "pwm_zero_after_fault_s": None,
                                        "standstill_after_fault_s": None,
                                        "travel_after_fault_m": None,
                                        "peak_speed_after_fault_mps": None}
        if self.fault_at is None or self.step_time.size == 0:
            return out
        at = self.fault_at
        t = self.step_time
        dt = float(t[1] - t[0]) if t.size > 1 else float(t[0])
        after = t > at + 1e-12
        out["travel_after_fault_m"] = float(np.max(np.sum(self.step_contact_speed[after], axis=0)) * dt) \
            if after.any() else 0.0
        out["peak_speed_after_fault_mps"] = float(self.step_speed[after].max()) if after.any() else 0.0
        powered = np.flatnonzero(np.any(self.step_volts != 0.0, axis=1))
        if not powered.size or powered[-1] < t.size - 1:
            # the step after the last powered one is the first unpowered for good
            zero_from = t[powered[-1] + 1] - dt if powered.size else 0.0
            out["pwm_zero_after_fault_s"] = max(0.0, float(zero_from) - at)
        moving = np.flatnonzero(self.step_speed >= STANDSTILL_SPEED)
        if not moving.size or moving[-1] < t.size - 1:
            still_from = t[moving[-1]] if moving.size else 0.0
            out["standstill_after_fault_s"] = max(0.0, float(still_from) - at)
        return out

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second."""
        return self.duration / self.wall_time if self.wall_time > 0 else math.inf

    def metrics(self) -> dict[str, object]:
        """The run's figures by name: the final pose of the ground truth and of each
        odometry with its errors, the tracking error, the caster totals, the
        port-vs-firmware differences, the line counts, the board's events and the fault
        figures (``fault_metrics``)."""
        tx, ty, tth = self.truth[-1]
        out: dict[str, object] = {
            "scenario": self.scenario, "backend": self.backend,
            "simulated_s": round(self.duration, 3), "ticks": self.ticks,
            "real_time_factor": round(self.real_time_factor, 1),
            "truth_x": tx, "truth_y": ty, "truth_heading_deg": math.degrees(tth),
        }
        for name, est in (("odom_wheel", self.odom_wheel), ("odom_velocity", self.odom_velocity),
                          ("odom_gyro", self.odom_gyro), ("odom_ekf", self.odom_ekf),
                          ("odom_ekf_vel", self.odom_ekf_vel)):
            if est is None:
                continue
            ex, ey, eth = est[-1]
            out[f"{name}_x"], out[f"{name}_y"] = ex, ey
            out[f"{name}_heading_deg"] = math.degrees(eth)
            out[f"{name}_position_error_m"] = math.hypot(ex - tx, ey - ty)
            out[f"{name}_heading_error_deg"] = math.degrees(_wrap(eth - tth))
        err = self.setpoint - self.measured
        out["tracking_rms_rad_s"] = float(np.sqrt(np.mean(err**2))) if err.size else 0.0
        out["caster_scrub_energy_j"] = self.caster_scrub_energy
        out["caster_scrub_time_s"] = self.caster_scrub_time
        out["caster_swivel_work_j"] = self.caster_swivel_work
        out["caster_side_impulse_ns"] = self.caster_side_impulse
        out["firmware_differences"] = self.firmware_differences
        out.update({f"lines_{k}": v for k, v in self.lines.items()})
        out["events"] = [[t, line] for t, line in self.events]
        out["boots"] = [[t, line] for t, line in self.boots]
        out.update(self.fault_metrics())
        out["closed_loop"] = self.goal is not None
        if self.goal is not None:
            gx, gy = self.goal
            error = math.hypot(tx - gx, ty - gy)
            out.update(goal_x=gx, goal_y=gy, goal_error_m=error, goal_reached_s=self.goal_reached_s,
                       goal_tolerance_m=self.goal_tolerance, steered_by=self.steered_by,
                       goal_within_tolerance=self.goal_reached_s is not None
                       and error <= (self.goal_tolerance or 0.0))
        return out


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class _Host:
    """The navigation host: parses feedback lines and keeps three odometries."""

    def __init__(self, plant_params, gyro: Gyro, ekf: bool = False) -> None:
        op = OdometryParams(wheel_radius=plant_params.wheel_radius, wheelbase=plant_params.wheelbase,
                            counts_per_rev=plant_params.counts_per_rev)
        self.decoder = LineDecoder()
        self.position = WheelOdometry(op, "position")
        self.velocity = WheelOdometry(op, "velocity")
        self.gyro_odom = WheelOdometry(op, "position")
        self.gyro = gyro
        self.integrator = GyroIntegrator()
        self.ekf = Ekf2D()
        self.ekf_vel = Ekf2D(EkfConfig.wheel_velocities())
        #: The EKFs run only when asked (``run(..., ekf=True)``): at the gyro's 400 Hz they
        #: take 9 times as long as the rest of the run.
        self.ekfs: tuple[Ekf2D, ...] = (self.ekf, self.ekf_vel) if ekf else ()
        self._gyro_index = 0
        self._idle_ekf_poses: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
        self.lines = {"feedback": 0, "error": 0, "event": 0, "other": 0}

    def receive(self, t: float, data: bytes) -> None:
        for msg in self.decoder.feed(data):
            if isinstance(msg, Feedback):
                self.lines["feedback"] += 1
                times, rates = self.gyro.times, self.gyro.rates
                upto = bisect.bisect_right(times, t, self._gyro_index)
                if not self.ekfs:
                    self.integrator.add_many(times, rates, self._gyro_index, upto)
                for i in range(self._gyro_index, upto) if self.ekfs else ():
                    self.integrator.add(times[i], rates[i])
                    for ekf in self.ekfs:
                        ekf.imu(times[i], self.integrator.heading, rates[i])
                self._gyro_index = upto
                self.position.integrate(t, msg.count_left, msg.count_right)
                self.velocity.integrate(t, msg.count_left, msg.count_right)
                v = self.velocity
                for ekf in self.ekfs:
                    ekf.odometry(t, v.pose.x, v.pose.y, v.pose.theta, v.linear, v.angular)
                self.gyro_odom.use_gyro_heading(self.integrator.heading_at(t))
                self.gyro_odom.integrate(t, msg.count_left, msg.count_right)
            else:
                key = type(msg).__name__.lower()
                self.lines[key if key in self.lines else "other"] += 1

    def poses(self) -> tuple[tuple[float, float, float], ...]:
        p, v, g = self.position.pose, self.velocity.pose, self.gyro_odom.pose
        if self.ekfs:
            ekf, ekf_vel = self.ekf.pose, self.ekf_vel.pose
        else:                           # filters that never run: their first pose, kept
            if self._idle_ekf_poses is None:
                self._idle_ekf_poses = (self.ekf.pose, self.ekf_vel.pose)
            ekf, ekf_vel = self._idle_ekf_poses
        return (p.x, p.y, p.theta), (v.x, v.y, v.theta), (g.x, g.y, g.theta), ekf, ekf_vel


class _Pilot:
    """The closed-loop host: every host period, a ``cmdvel`` from pure pursuit
    (``wcdrive.sim.navigation``) on its own estimate (wheel odometry or the EKF); after the
    goal, stops for ``settle_s``."""

    def __init__(self, scenario: Scenario, host: _Host) -> None:
        assert scenario.path is not None
        self.ctl = PurePursuit(scenario.path, scenario.follow)
        self.host = host
        self.localization = scenario.follow.localization
        self.period = round(F_CPU / scenario.host_rate_hz)
        self.next = round(0.02 * F_CPU)
        self.settle = round(scenario.settle_s * F_CPU)
        self.sent: list[tuple[int, bytes]] = []
        self.done_at: int | None = None

    def pose(self) -> tuple[float, float, float]:
        if self.localization == "ekf":
            return self.host.ekf_vel.pose
        p = self.host.position.pose
        return p.x, p.y, p.theta

    def step(self) -> tuple[int, bytes]:
        """The command due at ``next``; moves ``next`` on a period."""
        cycle = self.next
        v, w, done = self.ctl.command(*self.pose())
        if done and self.done_at is None:
            self.done_at = cycle
        data = encode_cmdvel(v, w)
        self.sent.append((cycle, data))
        self.next += self.period
        return cycle, data

    def finished(self) -> bool:
        """The goal was reached and the chair has had ``settle_s`` to stop."""
        return self.done_at is not None and self.next >= self.done_at + self.settle


#: The tick log's columns and their widths, in the order ``_Log.add`` writes them.
_LOG_COLUMNS = (("tick_time", 1), ("truth", 3), ("odom_wheel", 3), ("odom_velocity", 3), ("odom_gyro", 3),
                ("setpoint", 2), ("measured", 2), ("wheel_speed", 2), ("pwm", 2), ("caster", 2),
                ("counts", 2), ("odom_ekf", 3), ("odom_ekf_vel", 3))
_LOG_WIDTH = sum(width for _, width in _LOG_COLUMNS)


class _Log:
    """A row of numbers per control tick, kept flat in one ``array('d')``: no object
    per row outlives the tick, so the run leaves the garbage collector (paused for
    the run, ``cyclic_gc_paused``) nothing to scan when it comes back on."""

    def __init__(self) -> None:
        self._flat = array("d")
        self.tick_cycles: list[int] = []

    @property
    def ticks(self) -> int:
        return len(self.tick_cycles)

    def add(self, cycle: int, plant: Plant, host: _Host, setpoint, measured, pwm, counts) -> None:
        wheel, velocity, gyro, ekf, ekf_vel = host.poses()
        speed = plant.s.speed
        # the casters' world headings; ``arrays`` makes them relative to the chassis
        caster = plant.caster_heading
        self._flat.extend((cycle / F_CPU, *plant.pose, *wheel, *velocity, *gyro, setpoint[0], setpoint[1],
                           measured[0], measured[1], speed[0], speed[1], pwm[0], pwm[1], caster[0], caster[1],
                           counts[0], counts[1], *ekf, *ekf_vel))
        self.tick_cycles.append(cycle)

    def arrays(self) -> dict[str, np.ndarray]:
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


class _Lines:
    """The board's TX stream cut into lines, each stamped with the cycle of its last
    byte; keeps the ``EVT:`` and ``BOOT:`` lines."""

    def __init__(self) -> None:
        self._partial = bytearray()
        self.events: list[tuple[float, str]] = []
        self.boots: list[tuple[float, str]] = []
        # every line's time and text, apart: no object per line for the collector (``_Log``)
        self._times = array("d")
        self._texts: list[str] = []

    @property
    def all(self) -> list[tuple[float, str]]:
        """Every line as (s, text)."""
        return list(zip(self._times, self._texts, strict=True))

    def feed(self, cycle: int, data: bytes) -> None:
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
    if not by_last_byte:
        return at
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


def run(scenario: Scenario, *, backend: str = "port", seed: int = 0, dt: float = 0.001,
        progress: Callable[[float], None] | None = None, elf=None, ekf: bool = False) -> SimResult:
    """Runs ``scenario`` in closed loop: ``backend`` "port" (the Python port) or "simavr"
    (the ELF ``elf``, by default the bundled firmware, built if needed), the plant
    stepping every ``dt`` s, with the scenario's faults. ``seed`` seeds the gyro;
    ``progress`` is called now and then with the fraction done; ``ekf`` runs the seeds'
    EKFs (``odom_ekf``, ``odom_ekf_vel``) on the host too."""
    if backend not in ("port", "simavr"):
        raise ValueError("backend must be 'port' or 'simavr'")
    if not 1e-5 <= dt <= 0.01:
        raise ValueError("dt must be within 10 us .. 10 ms")
    params = scenario.params()
    plant = Plant(params)
    plant.start_motion_log()
    gyro = Gyro(params, seed)
    closed = scenario.closed_loop
    host = _Host(params, gyro, ekf or (closed and scenario.follow.localization == "ekf"))
    pilot = _Pilot(scenario, host) if closed else None
    log = _Log()
    lines = _Lines()
    step_cycles = round(dt * F_CPU)
    end_cycle = round(scenario.duration * F_CPU)
    commands = [(round(t * F_CPU), data) for t, data in scenario.host_commands()
                if t < scenario.duration and not (closed and t >= 0.02)]   # closed: params only
    wire = wire_schedule(commands, scenario.faults)
    wall0 = time.perf_counter()
    with cyclic_gc_paused():
        if backend == "port":
            extra = _run_port(plant, gyro, host, log, lines, wire, scenario.faults, end_cycle, dt, progress,
                              pilot)
        else:
            extra = _run_simavr(plant, gyro, host, log, lines, wire, scenario.faults, step_cycles, end_cycle,
                                dt, progress, elf, pilot)
    wall = time.perf_counter() - wall0
    duration = extra.pop("end_cycle", end_cycle) / F_CPU
    goal: dict[str, object] = {}
    if pilot is not None:
        commands += pilot.sent
        goal = {"goal": pilot.ctl.goal, "goal_tolerance": scenario.follow.truth_tolerance,
                "goal_reached_s": None if pilot.done_at is None else pilot.done_at / F_CPU,
                "steered_by": scenario.follow.localization}
    motion = plant.take_motion_log()
    half = 0.5 * params.wheelbase
    contact = np.stack((np.hypot(motion[:, 1] - motion[:, 3] * half, motion[:, 2]),
                        np.hypot(motion[:, 1] + motion[:, 3] * half, motion[:, 2])), axis=1)
    return SimResult(scenario=scenario.name, backend=backend, duration=duration, wall_time=wall,
                     ticks=log.ticks, caster_scrub_energy=plant.caster_scrub_energy,
                     caster_scrub_time=plant.caster_scrub_time, caster_swivel_work=plant.caster_swivel_work,
                     caster_side_impulse=plant.caster_side_impulse, lines=dict(host.lines),
                     step_time=motion[:, 0], step_speed=contact.max(axis=1) if contact.size else np.zeros(0),
                     step_contact_speed=contact, step_volts=motion[:, 4:6],
                     events=lines.events, boots=lines.boots, faults=scenario.faults,
                     fault_at=fault_time(scenario, wire),
                     gyro_time=np.array(gyro.times), gyro_rate=np.array(gyro.rates),
                     serial_lines=lines.all, cmd_vel=_cmd_vel(commands),
                     **goal, **extra, **_without_ekf(log.arrays(), ekf))  # type: ignore[arg-type]


def _without_ekf(arrays: dict[str, np.ndarray], ekf: bool) -> dict[str, np.ndarray]:
    if not ekf:
        arrays.pop("odom_ekf")
        arrays.pop("odom_ekf_vel")
    return arrays


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


def _run_port(plant, gyro, host, log, lines, wire, faults, end_cycle, dt, progress,
              pilot: _Pilot | None = None) -> dict:
    loop = PortLoop(plant, gyro, dt, faults=faults)
    for cycle, data in wire.runs:
        loop.send(data, at=cycle)
    last_progress = [0.0]

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
        if progress and t - last_progress[0] > 1.0:
            progress(t * F_CPU / end_cycle)
            last_progress[0] = t

    if pilot is None:
        loop.run_until(end_cycle, on_tick)
        take()
        return {}
    while pilot.next < end_cycle and not pilot.finished():
        loop.run_until(pilot.next, on_tick)
        take()
        cycle, data = pilot.step()
        loop.send(data, at=cycle)
    end = min(pilot.next, end_cycle)
    loop.run_until(end, on_tick)
    take()
    return {"end_cycle": end}


def _run_simavr(plant, gyro, host, log, lines, wire, faults, step_cycles, end_cycle, dt, progress,
                elf, pilot: _Pilot | None = None) -> dict:
    mega = VirtualMega(elf)
    recorder = Recorder(mega)
    pins = PlantOnPins(mega, plant, gyro, faults=faults)
    trains: dict[str, list[EdgeTrain]] = {"left": [], "right": []}
    tx_seen = 0
    n_events_logged = 0
    runs = wire.runs
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
        if len(mega.tx_log) > tx_seen:
            fresh = mega.tx_log[tx_seen:]
            host.receive(t1, bytes(b for _, b in fresh))
            lines.feed_stamped(fresh)
            tx_seen = len(mega.tx_log)
        for ev in recorder.events[n_events_logged:]:
            if ev.kind == "tick" and ev.after:
                a = ev.after
                log.add(ev.cycle, plant, host, (a["setpointL"], a["setpointR"]),
                        (a["filtVelL"], a["filtVelR"]),
                        (_signed(int(a["pwmL"]), int(a["dirL"])), _signed(int(a["pwmR"]), int(a["dirR"]))),
                        (int(a["encTickL"]), int(a["encTickR"])))
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
    out = {"firmware_differences": len(report.mismatches), "firmware_events_compared": report.events}
    if pilot is not None:
        out["end_cycle"] = end_cycle
    return out
