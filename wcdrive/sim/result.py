"""What one ``wcdrive sim`` run gives (``SimResult``), in a few records: the plant's
ground truth, the board's state at every control tick, the serial link both ways, the
host's odometries, and, where they apply, the closed loop's goal and the comparison of
the compiled firmware with the port.

The fault figures (``SimResult.fault_metrics``) and the stop figures
(``SimResult.stop_metrics``) come from the ground truth of the plant's motion after every
physics step: the chair's speed is that of the faster of its two drive-wheel contact
points (so a chair spinning on the spot is not "still"), and its travel the longer of
their two paths. The drift of a parked chair is the axle midpoint's distance from where
it came to rest, by its pose at every control tick.

A scenario with walls or a start pose (``[world]``) adds ``SimResult.world``: where the
chair started and its collisions with the walls (``wcdrive.plant.chair.Contacts``). The
ground truth is in the map frame; the host's odometries start at their own (0, 0, 0),
so the figures compare them with it placed at the start pose (``placed``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from wcdrive.boards.port_loop import F_CPU
from wcdrive.plant.chair import Contact
from wcdrive.plant.faults import Fault
from wcdrive.plant.lidar import LaserScan, Lidar
from wcdrive.plant.rosmap import OccupancyGrid
from wcdrive.plant.terrain import Terrain

#: m/s: the chair is at a standstill once its speed stays below this.
STANDSTILL_SPEED = 0.01


def _empty(*shape: int) -> np.ndarray:
    return np.zeros(shape)


@dataclass
class GroundTruth:
    """The plant's motion: a row per control tick (as ``BoardLog.tick_time``), a row per
    physics step (``step_*``), and the casters' totals over the run."""

    pose: np.ndarray            # (n, 3): x, y, heading at each tick
    wheel_speed: np.ndarray     # (n, 2): true wheel speed (rad/s)
    caster: np.ndarray          # (n, 2): caster swivel angles relative to the chassis (rad)
    caster_scrub_energy: float = 0.0
    caster_scrub_time: float = 0.0
    caster_swivel_work: float = 0.0
    caster_side_impulse: float = 0.0
    #: Per physics step: the time at its end (s), the chair's speed (m/s, module
    #: docstring), the wheels' contact speeds (left, right; m/s) and the motor
    #: voltages the driver applied over it (left, right; V, signed).
    step_time: np.ndarray = field(default_factory=lambda: _empty(0))
    step_speed: np.ndarray = field(default_factory=lambda: _empty(0))
    step_contact_speed: np.ndarray = field(default_factory=lambda: _empty(0, 2))
    step_volts: np.ndarray = field(default_factory=lambda: _empty(0, 2))
    #: Each motor's winding temperature at each tick (left, right; deg C).
    winding_temp: np.ndarray = field(default_factory=lambda: _empty(0, 2))
    #: The battery at each tick: its terminal voltage (V; the ideal supply's without a
    #: battery model) and its state of charge (0..1).
    battery: np.ndarray = field(default_factory=lambda: _empty(0, 2))


@dataclass
class BoardLog:
    """The firmware's state at every control tick, a row per tick (columns as noted)."""

    tick_time: np.ndarray       # (n,): s
    setpoint: np.ndarray        # (n, 2): left, right ramped setpoints (rad/s)
    measured: np.ndarray        # (n, 2): filtered wheel speed the PID saw
    pwm: np.ndarray             # (n, 2): signed duty (-255..255)
    counts: np.ndarray          # (n, 2): the encoder counts the tick latched (left, right)
    #: The cycle of every control tick.
    tick_cycles: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


@dataclass
class LinkLog:
    """The serial link both ways: every line the board sent, its ``EVT:`` and ``BOOT:``
    lines, as (s, line); the host's count of the lines by kind; the host's velocity
    commands as (s, m/s, rad/s)."""

    lines: list[tuple[float, str]] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)
    boots: list[tuple[float, str]] = field(default_factory=list)
    line_counts: dict[str, int] = field(default_factory=dict)
    cmd_vel: list[tuple[float, float, float]] = field(default_factory=list)


@dataclass
class Odometry:
    """The host's pose estimates at every control tick, (n, 3) each (x, y, heading), and
    the gyro's samples (s, rad/s) they read."""

    wheel: np.ndarray           # position-based wheel odometry
    velocity: np.ndarray        # velocity-based
    gyro: np.ndarray            # wheel distance + gyro heading
    #: The seeds' EKF (``wcdrive.navigation.ekf``) on velocity odometry and the
    #: gyro: seed 000's ekf.yaml (wheels: x, y, vx), and seed 002's scheme (wheels: vx, vy).
    #: None unless the run asked for them (``run(..., ekf=True)``).
    ekf: np.ndarray | None = None
    ekf_vel: np.ndarray | None = None
    gyro_time: np.ndarray = field(default_factory=lambda: _empty(0))
    gyro_rate: np.ndarray = field(default_factory=lambda: _empty(0))


@dataclass
class Goal:
    """A closed-loop run (a ``path`` scenario): the goal (m), the time the host's estimate
    reached it (None: never), the published bound on the true error (m) and which
    estimate the host steered by."""

    position: tuple[float, float]
    reached_s: float | None
    tolerance: float
    steered_by: str


@dataclass
class Lockstep:
    """The compiled firmware's events replayed on the port (simavr backend): how many
    differed, of how many compared."""

    differences: int
    events_compared: int


@dataclass
class WorldLog:
    """The chair among the scenario's walls (``[world]``): its start pose in the map frame
    (x, y in m, heading in rad), the walls (``segments`` (N, 4) and ``circles`` (M, 3),
    as ``wcdrive.plant.world.World`` has them; empty without any), and its collisions
    (``wcdrive.plant.chair.Contacts``): how many, the first one's time (s; None: none),
    the largest impact (N s), the time it spent touching (s) and the records the plant
    kept (``Contacts.records``)."""

    start: tuple[float, float, float]
    segments: np.ndarray = field(default_factory=lambda: _empty(0, 4))
    circles: np.ndarray = field(default_factory=lambda: _empty(0, 3))
    collisions: int = 0
    first_collision_s: float | None = None
    max_impact_ns: float = 0.0
    contact_s: float = 0.0
    contacts: list[Contact] = field(default_factory=list)
    #: The ROS map the walls came from, if they came from one (``/map``).
    grid: OccupancyGrid | None = None

    @property
    def walled(self) -> bool:
        """Whether there are walls to collide with."""
        return bool(len(self.segments) or len(self.circles))


@dataclass
class LidarLog:
    """The lidar on the chair (the scenario's ``[lidar]``) and the scans it took, one a
    turn from 0 s on (``wcdrive.sim.scanning``), as its ROS driver publishes them."""

    lidar: Lidar
    scans: list[LaserScan] = field(default_factory=list)


def placed(start: tuple[float, float, float], poses: np.ndarray) -> np.ndarray:
    """Odometry poses ``(n, 3)`` (x, y, heading from the odometry's own origin) in the map
    frame of a chair that started at ``start``."""
    x0, y0, th0 = start
    c, s = math.cos(th0), math.sin(th0)
    out = np.empty_like(poses)
    out[:, 0] = x0 + c * poses[:, 0] - s * poses[:, 1]
    out[:, 1] = y0 + s * poses[:, 0] + c * poses[:, 1]
    out[:, 2] = poses[:, 2] + th0
    return out


@dataclass
class SimResult:
    """One run of a scenario: the ground truth, the board's ticks, the link, the host's
    odometries, the closed loop's goal (None: open loop) and, with the simavr backend,
    the comparison of the firmware with the port (None on the port)."""

    scenario: str
    backend: str
    duration: float
    wall_time: float
    truth: GroundTruth
    board: BoardLog
    odometry: Odometry
    link: LinkLog = field(default_factory=LinkLog)
    faults: tuple[Fault, ...] = ()
    #: ``fault_metrics``: when the fault figures count from (None: no fault, no silence).
    fault_at: float | None = None
    goal: Goal | None = None
    lockstep: Lockstep | None = None
    #: ``stop_metrics``: when the run's last stop began (``wcdrive.sim.runner.stop_time``;
    #: None: the run ends without one).
    stop_at: float | None = None
    #: The floor the chair stood on (the scenario's ``[world]``).
    terrain: Terrain = field(default_factory=Terrain)
    #: The walls and the start pose (the scenario's ``[world]``); None: neither.
    world: WorldLog | None = None
    #: The lidar and its scans (the scenario's ``[lidar]``); None: no lidar.
    lidar: LidarLog | None = None

    @property
    def ticks(self) -> int:
        """How many control ticks the board ran."""
        return len(self.board.tick_cycles)

    @property
    def firmware_differences(self) -> int | None:
        """``lockstep.differences`` (None on the port)."""
        return None if self.lockstep is None else self.lockstep.differences

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
        ticks = self.board.tick_cycles
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
        truth = self.truth
        if self.fault_at is None or truth.step_time.size == 0:
            return out
        at = self.fault_at
        t = truth.step_time
        dt = _step(t)
        after = t > at + 1e-12
        out["travel_after_fault_m"] = _travel(truth, after, dt)
        out["peak_speed_after_fault_mps"] = _peak(truth, after)
        powered = np.flatnonzero(np.any(truth.step_volts != 0.0, axis=1))
        if not powered.size or powered[-1] < t.size - 1:
            # the step after the last powered one is the first unpowered for good
            zero_from = t[powered[-1] + 1] - dt if powered.size else 0.0
            out["pwm_zero_after_fault_s"] = max(0.0, float(zero_from) - at)
        moving = np.flatnonzero(truth.step_speed >= STANDSTILL_SPEED)
        if not moving.size or moving[-1] < t.size - 1:
            still_from = t[moving[-1]] if moving.size else 0.0
            out["standstill_after_fault_s"] = max(0.0, float(still_from) - at)
        return out

    def stop_metrics(self, parked_s: float | None = None) -> dict[str, float | None]:
        """The stop figures, counted from ``stop_at`` (the start of the run's last stop:
        a stop command, the last byte before a silence or a link cut, a fault; see
        ``wcdrive.sim.runner.stop_time``), by the plant's ground truth (module
        docstring):

        * ``stop_at_s``;
        * ``max_speed_after_stop_mps``: the chair's largest speed after it;
        * ``rest_at_s``: the first moment after it at which the chair's speed is below
          ``STANDSTILL_SPEED``: there the chair came to rest;
        * ``stopping_time_s``, ``stopping_distance_m``: from the stop to that rest;
        * ``travel_after_stop_m``: from the stop to the end of the run;
        * ``drift_parked_m``: the largest distance the axle midpoint moves from where it
          came to rest, over the rest of the run (or over the ``parked_s`` seconds
          after it), by its pose at every control tick (where it came to rest
          interpolated between two). Counted from the first rest, so that a chair that
          rests, rolls and rests again shows the roll.

        Every figure is None where there is no stop; those from the rest on are None
        where the chair never came to rest."""
        out: dict[str, float | None] = dict.fromkeys(
            ("stop_at_s", "max_speed_after_stop_mps", "rest_at_s", "stopping_time_s", "stopping_distance_m",
             "travel_after_stop_m", "drift_parked_m"))
        truth, at = self.truth, self.stop_at
        if at is None or truth.step_time.size == 0:
            return out
        t = truth.step_time
        dt = _step(t)
        after = t > at + 1e-12
        out["stop_at_s"] = at
        out["max_speed_after_stop_mps"] = _peak(truth, after)
        out["travel_after_stop_m"] = _travel(truth, after, dt)
        resting = np.flatnonzero(after & (truth.step_speed < STANDSTILL_SPEED))
        if not resting.size:
            return out
        rest = float(t[resting[0]])
        out["rest_at_s"] = rest
        out["stopping_time_s"] = rest - at
        out["stopping_distance_m"] = _travel(truth, after & (t <= rest + 1e-12), dt)
        ticks, pose = self.board.tick_time, truth.pose
        until = math.inf if parked_s is None else rest + parked_s + 1e-12
        parked = (ticks >= rest - 1e-12) & (ticks <= until)
        # where it came to rest: between two ticks, interpolated (before the first, the first)
        x0, y0 = (float(np.interp(rest, ticks, pose[:, i])) for i in (0, 1))
        where = pose[parked, :2]
        out["drift_parked_m"] = float(np.max(np.hypot(where[:, 0] - x0, where[:, 1] - y0))) \
            if where.size else 0.0
        return out

    def slope_by_time(self) -> list[list[float]]:
        """The grade of the floor under the axle midpoint over the run, as ranges
        ``[from_s, to_s, slope_deg]``, by the pose at every control tick: each from the
        first tick on that grade to the first on the next (the first range from 0, the
        last to the end of the run); one range on a uniform floor."""
        ticks, pose = self.board.tick_time, self.truth.pose
        if self.ticks == 0:
            return [[0.0, self.duration, self.terrain.slope_deg]]
        grades = [self.terrain.grade_at(x, y)[0] for x, y in pose[:, :2]]
        out: list[list[float]] = []
        for k, grade in enumerate(grades):
            if not out or grade != grades[k - 1]:
                if out:
                    out[-1][1] = float(ticks[k])
                out.append([float(ticks[k]) if out else 0.0, self.duration, math.degrees(grade)])
        return out

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall second."""
        return self.duration / self.wall_time if self.wall_time > 0 else math.inf

    def metrics(self) -> dict[str, object]:
        """The run's figures by name: the final pose of the ground truth and of each
        odometry with its errors, the tracking error, the caster totals, the
        port-vs-firmware differences, the line counts, the board's events (``events``:
        ``[s, line]`` for every ``EVT:`` line), the fault figures (``fault_metrics``), the
        floor and the stop figures (``stop_metrics``); ``winding_temp_max_c``, the hotter
        motor winding's highest temperature (deg C; None without a tick);
        ``battery_min_v``, the battery's lowest terminal voltage at a tick (V); ``distance_m``,
        the length of the chair's true path (m, tick to tick).

        The floor: ``slope_deg`` and ``downhill_heading_deg`` (the ``[world]`` table's
        uniform grade and the heading it falls toward, degrees), ``ramps`` (its bands,
        ``{"from_x", "to_x", "slope_deg"}`` each; empty on a uniform floor) and
        ``slope_by_time`` (the grade the chair stood on, ``[from_s, to_s, slope_deg]``
        ranges: ``slope_by_time``).

        With ``world``: ``start_x``, ``start_y``, ``start_heading_deg``; the odometries'
        poses and errors with the odometry placed at the start (``placed``; a path's goal
        likewise); and with walls, the collisions: ``collisions`` (how many),
        ``first_collision_s`` (None: none), ``max_impact_ns`` (the largest impact, N s),
        ``contact_s`` (s touching) and ``contact_records`` (``[time_s, x, y, impact_ns]``
        for each record the plant kept)."""
        truth, odometry, link, world = self.truth, self.odometry, self.link, self.world
        tx, ty, tth = truth.pose[-1]
        out: dict[str, object] = {
            "scenario": self.scenario, "backend": self.backend,
            "simulated_s": round(self.duration, 3), "ticks": self.ticks,
            "real_time_factor": round(self.real_time_factor, 1),
            "truth_x": tx, "truth_y": ty, "truth_heading_deg": math.degrees(tth),
        }
        for name, est in (("odom_wheel", odometry.wheel), ("odom_velocity", odometry.velocity),
                          ("odom_gyro", odometry.gyro), ("odom_ekf", odometry.ekf),
                          ("odom_ekf_vel", odometry.ekf_vel)):
            if est is None:
                continue
            ex, ey, eth = est[-1] if world is None else placed(world.start, est[-1:])[0]
            out[f"{name}_x"], out[f"{name}_y"] = ex, ey
            out[f"{name}_heading_deg"] = math.degrees(eth)
            out[f"{name}_position_error_m"] = math.hypot(ex - tx, ey - ty)
            out[f"{name}_heading_error_deg"] = math.degrees(_wrap(eth - tth))
        err = self.board.setpoint - self.board.measured
        out["tracking_rms_rad_s"] = float(np.sqrt(np.mean(err**2))) if err.size else 0.0
        out["caster_scrub_energy_j"] = truth.caster_scrub_energy
        out["caster_scrub_time_s"] = truth.caster_scrub_time
        out["caster_swivel_work_j"] = truth.caster_swivel_work
        out["caster_side_impulse_ns"] = truth.caster_side_impulse
        temps = truth.winding_temp
        out["winding_temp_max_c"] = float(temps.max()) if temps.size else None
        volts = truth.battery[:, 0] if truth.battery.size else truth.battery
        out["battery_min_v"] = float(volts.min()) if volts.size else None
        out["distance_m"] = float(np.hypot(*np.diff(truth.pose[:, :2], axis=0).T).sum())
        out["firmware_differences"] = self.firmware_differences
        out.update({f"lines_{k}": v for k, v in link.line_counts.items()})
        out["events"] = [[t, line] for t, line in link.events]
        out["boots"] = [[t, line] for t, line in link.boots]
        out.update(self.fault_metrics())
        terrain = self.terrain
        out["slope_deg"] = terrain.slope_deg
        out["downhill_heading_deg"] = terrain.downhill_heading_deg
        out["ramps"] = [{"from_x": r.from_x, "to_x": r.to_x, "slope_deg": r.slope_deg} for r in terrain.ramps]
        out["slope_by_time"] = self.slope_by_time()
        out.update(self.stop_metrics())
        if world is not None:
            out["start_x"], out["start_y"] = world.start[0], world.start[1]
            out["start_heading_deg"] = math.degrees(world.start[2])
            if world.walled:
                out.update(collisions=world.collisions, first_collision_s=world.first_collision_s,
                           max_impact_ns=world.max_impact_ns, contact_s=world.contact_s,
                           contact_records=[[c.time, c.x, c.y, c.impact] for c in world.contacts])
        if self.lidar is not None:
            from wcdrive.sim.scanning import scan_summary

            lidar = self.lidar.lidar
            mount = lidar.mount
            out.update(lidar_model=lidar.model.name, lidar_mount=[mount.x, mount.y, mount.z, mount.yaw_deg],
                       lidar_inverted=mount.inverted, lidar_driver_inverted=mount.driver_inverted)
            out.update(scan_summary(self.lidar.scans))
        out["closed_loop"] = self.goal is not None
        if self.goal is not None:
            goal = self.goal
            gx, gy = goal.position
            if world is not None:
                gx, gy, _ = placed(world.start, np.array([[gx, gy, 0.0]]))[0]
            error = math.hypot(tx - gx, ty - gy)
            out.update(goal_x=gx, goal_y=gy, goal_error_m=error, goal_reached_s=goal.reached_s,
                       goal_tolerance_m=goal.tolerance, steered_by=goal.steered_by,
                       goal_within_tolerance=goal.reached_s is not None
                       and error <= (goal.tolerance or 0.0))
        return out


def _step(t: np.ndarray) -> float:
    """s: the physics step of the motion log whose step end times are ``t``."""
    return float(t[1] - t[0]) if t.size > 1 else float(t[0])


def _travel(truth: GroundTruth, steps: np.ndarray, dt: float) -> float:
    """m: the longer of the two contact points' paths over the ``steps`` (a mask)."""
    return float(np.max(np.sum(truth.step_contact_speed[steps], axis=0)) * dt) if steps.any() else 0.0


def _peak(truth: GroundTruth, steps: np.ndarray) -> float:
    """m/s: the chair's largest speed over the ``steps`` (a mask); 0 for none."""
    return float(truth.step_speed[steps].max()) if steps.any() else 0.0


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi
