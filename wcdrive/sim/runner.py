"""The closed loop: a scenario's host, the firmware (the port, or the ELF in simavr),
and the pymunk chair, at the firmware's own timing.

Time runs in 16 MHz cycles (``wcdrive.boards.port_loop``); the plant steps at a fixed
``dt`` (1 kHz by default) and sees the PWM/DIR of the last control tick.

* ``backend="port"``: the bit-exact Python port (``PortLoop``).
* ``backend="simavr"``: the compiled firmware, fed the plant's encoder edges at
  their exact times and the host's bytes at wire speed. Every firmware event is
  recorded, and at the end the port replays them (``wcdrive.hil.lockstep``) so the report
  gives the differences in the firmware outputs between the two (expected: none).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.hil.lockstep import Recorder, compare
from wcdrive.hil.traces import Trace
from wcdrive.odometry import GyroIntegrator, OdometryParams, WheelOdometry
from wcdrive.plant import Gyro, Plant
from wcdrive.plant.encoders import EdgeTrain
from wcdrive.protocol.codec import Feedback, LineDecoder
from wcdrive.sim.scenario import Scenario


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
    caster_scrub_energy: float
    caster_scrub_time: float
    caster_swivel_work: float
    caster_side_impulse: float
    firmware_differences: int | None = None
    firmware_events_compared: int | None = None
    lines: dict[str, int] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second."""
        return self.duration / self.wall_time if self.wall_time > 0 else math.inf

    def metrics(self) -> dict[str, float | int | str | None]:
        """The run's figures by name: the final pose of the ground truth and of each
        odometry with its errors, the tracking error, the caster totals, the
        port-vs-firmware differences and the line counts."""
        tx, ty, tth = self.truth[-1]
        out: dict[str, float | int | str | None] = {
            "scenario": self.scenario, "backend": self.backend,
            "simulated_s": round(self.duration, 3), "ticks": self.ticks,
            "real_time_factor": round(self.real_time_factor, 1),
            "truth_x": tx, "truth_y": ty, "truth_heading_deg": math.degrees(tth),
        }
        for name, est in (("odom_wheel", self.odom_wheel), ("odom_velocity", self.odom_velocity),
                          ("odom_gyro", self.odom_gyro)):
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
        return out


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class _Host:
    """The navigation host: parses feedback lines and keeps three odometries."""

    def __init__(self, plant_params, gyro: Gyro) -> None:
        op = OdometryParams(wheel_radius=plant_params.wheel_radius, wheelbase=plant_params.wheelbase,
                            counts_per_rev=plant_params.counts_per_rev)
        self.decoder = LineDecoder()
        self.position = WheelOdometry(op, "position")
        self.velocity = WheelOdometry(op, "velocity")
        self.gyro_odom = WheelOdometry(op, "position")
        self.gyro = gyro
        self.integrator = GyroIntegrator()
        self._gyro_index = 0
        self.lines = {"feedback": 0, "error": 0, "event": 0, "other": 0}

    def receive(self, t: float, data: bytes) -> None:
        for msg in self.decoder.feed(data):
            if isinstance(msg, Feedback):
                self.lines["feedback"] += 1
                times, rates = self.gyro.times, self.gyro.rates
                while self._gyro_index < len(times) and times[self._gyro_index] <= t:
                    self.integrator.add(times[self._gyro_index], rates[self._gyro_index])
                    self._gyro_index += 1
                self.position.update(t, msg.count_left, msg.count_right)
                self.velocity.update(t, msg.count_left, msg.count_right)
                self.gyro_odom.use_gyro_heading(self.integrator.heading_at(t))
                self.gyro_odom.update(t, msg.count_left, msg.count_right)
            else:
                key = type(msg).__name__.lower()
                self.lines[key if key in self.lines else "other"] += 1

    def poses(self) -> tuple[tuple[float, float, float], ...]:
        return tuple((o.pose.x, o.pose.y, o.pose.theta)
                     for o in (self.position, self.velocity, self.gyro_odom))


class _Log:
    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def add(self, t: float, plant: Plant, host: _Host, setpoint, measured, pwm) -> None:
        wheel, velocity, gyro = host.poses()
        heading = plant.pose[2]
        caster = tuple(_wrap(c - heading) for c in plant.caster_heading)
        self.rows.append((t, plant.pose, wheel, velocity, gyro, setpoint, measured,
                          (plant.left.speed, plant.right.speed), pwm, caster))

    def arrays(self) -> dict[str, np.ndarray]:
        if not self.rows:
            z3, z2 = np.zeros((1, 3)), np.zeros((1, 2))
            return {"tick_time": np.zeros(1), "truth": z3, "odom_wheel": z3, "odom_velocity": z3,
                    "odom_gyro": z3, "setpoint": z2, "measured": z2, "wheel_speed": z2, "pwm": z2,
                    "caster": z2}
        cols = list(zip(*self.rows, strict=True))
        names = ("tick_time", "truth", "odom_wheel", "odom_velocity", "odom_gyro", "setpoint",
                 "measured", "wheel_speed", "pwm", "caster")
        return {n: np.array(c, dtype=float) for n, c in zip(names, cols, strict=True)}


def _signed(pwm: int, direction: int) -> int:
    return pwm if direction else -pwm


def run(scenario: Scenario, *, backend: str = "port", seed: int = 0, dt: float = 0.001,
        progress: Callable[[float], None] | None = None, elf=None) -> SimResult:
    """Runs ``scenario`` in closed loop: ``backend`` "port" (the Python port) or "simavr"
    (the ELF ``elf``, by default the bundled firmware, built if needed), the plant
    stepping every ``dt`` s. ``seed`` seeds the gyro; ``progress`` is called now and
    then with the fraction done."""
    if backend not in ("port", "simavr"):
        raise ValueError("backend must be 'port' or 'simavr'")
    if not 1e-5 <= dt <= 0.01:
        raise ValueError("dt must be within 10 us .. 10 ms")
    params = scenario.params()
    plant = Plant(params)
    gyro = Gyro(params, seed)
    host = _Host(params, gyro)
    log = _Log()
    step_cycles = round(dt * F_CPU)
    end_cycle = round(scenario.duration * F_CPU)
    commands = [(round(t * F_CPU), data) for t, data in scenario.host_commands()
                if t < scenario.duration]
    wall0 = time.perf_counter()
    if backend == "port":
        extra = _run_port(plant, gyro, host, log, commands, step_cycles, end_cycle, dt, progress)
    else:
        extra = _run_simavr(plant, gyro, host, log, commands, step_cycles, end_cycle, dt, progress, elf)
    wall = time.perf_counter() - wall0
    return SimResult(scenario=scenario.name, backend=backend, duration=scenario.duration, wall_time=wall,
                     ticks=len(log.rows), caster_scrub_energy=plant.caster_scrub_energy,
                     caster_scrub_time=plant.caster_scrub_time, caster_swivel_work=plant.caster_swivel_work,
                     caster_side_impulse=plant.caster_side_impulse, lines=dict(host.lines),
                     **extra, **log.arrays())  # type: ignore[arg-type]


def _run_port(plant, gyro, host, log, commands, step_cycles, end_cycle, dt, progress) -> dict:
    loop = PortLoop(plant, gyro, dt)
    for cycle, data in commands:
        loop.send(data, at=cycle)
    last_progress = [0.0]

    def on_tick(t: float) -> None:
        for cycle, out in loop.take_output():
            host.receive(cycle / F_CPU, out)
        s = loop.fw.state
        log.add(t, plant, host, (s.setpointL, s.setpointR), (s.filtVelL, s.filtVelR),
                (_signed(s.pwmL, s.dirL), _signed(s.pwmR, s.dirR)))
        if progress and t - last_progress[0] > 1.0:
            progress(t * F_CPU / end_cycle)
            last_progress[0] = t

    loop.run_until(end_cycle, on_tick)
    for cycle, out in loop.take_output():
        host.receive(cycle / F_CPU, out)
    return {}


def _run_simavr(plant, gyro, host, log, commands, step_cycles, end_cycle, dt, progress, elf) -> dict:
    mega = VirtualMega(elf)
    for cycle, data in commands:
        mega.send(data, at=cycle)
    recorder = Recorder(mega)
    pins = PlantOnPins(mega, plant, gyro)
    trains: dict[str, list[EdgeTrain]] = {"left": [], "right": []}
    tx_seen = 0
    n_events_logged = 0
    steps = end_cycle // step_cycles
    for k in range(steps):
        t0, t1 = k * dt, (k + 1) * dt
        for side, train in pins.step(t0, t1, recorder.run_until).items():
            if train.times.size:
                trains[side].append(train)
        if len(mega.tx_log) > tx_seen:
            host.receive(t1, bytes(b for _, b in mega.tx_log[tx_seen:]))
            tx_seen = len(mega.tx_log)
        for ev in recorder.events[n_events_logged:]:
            if ev.kind == "tick" and ev.after:
                a = ev.after
                log.add(ev.cycle / F_CPU, plant, host, (a["setpointL"], a["setpointR"]),
                        (a["filtVelL"], a["filtVelR"]),
                        (_signed(int(a["pwmL"]), int(a["dirL"])), _signed(int(a["pwmR"]), int(a["dirR"]))))
        n_events_logged = len(recorder.events)
        if progress and k % 1000 == 0:
            progress(k / steps)
    encoders = {}
    for side, parts in trains.items():
        if parts:
            encoders[side] = EdgeTrain(np.concatenate([p.times for p in parts]),
                                       np.concatenate([p.states for p in parts]), 0, 0)
    trace = Trace(duration=end_cycle / F_CPU, serial=[(c / F_CPU, d) for c, d in commands],
                  encoders=encoders)
    report = compare(recorder.recording(trace))
    mega.close()
    return {"firmware_differences": len(report.mismatches),
            "firmware_events_compared": report.events}
