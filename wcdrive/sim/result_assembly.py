"""What a scenario run gives, made from what it left: ``assemble_result`` turns a
finished run (its ``Rig``, its ``BackendRun``) into a ``SimResult``, with the times the
fault and stop figures count from (``fault_time``, ``stop_time``), the host's motion
commands as velocities and the world the plant met.

It runs once the backend is done and reads only what the run left in the rig, so one
assembly serves both backends; the figures' start times are taken from the wire
(``wcdrive.sim.wire``), where a lost link shows when its last byte really reached the
board.
"""

from __future__ import annotations

import re

import numpy as np

from wcdrive.boards.port_loop import F_CPU
from wcdrive.plant import ChairParams, Plant
from wcdrive.sim.backends import BackendRun, Rig
from wcdrive.sim.result import (
    BoardLog,
    Goal,
    GroundTruth,
    LidarLog,
    LinkLog,
    Odometry,
    SimResult,
    WorldLog,
)
from wcdrive.sim.scenario import Scenario, Segment
from wcdrive.sim.wire import WireSchedule, _last_byte_before

__all__ = ["assemble_result", "fault_time", "stop_time"]


def assemble_result(scenario: Scenario, params: ChairParams, rig: Rig, ran: BackendRun, *, backend: str,
                    wall: float, commands: list[tuple[int, bytes]], ekf: bool) -> SimResult:
    """The ``SimResult`` of the run of ``scenario`` (its chair ``params``) on ``rig``,
    which ended as ``ran`` says: the plant's ground truth (its motion log taken), the
    board's and the host's logs, the link's lines with the host's motion commands
    (``commands``, (cycle, bytes), and the pilot's), the goal, the world, the lidar's
    scans, and when the fault and stop figures count from. ``backend`` is the
    backend's name, ``wall`` the run's wall time (s), ``ekf`` whether the host ran the
    EKFs."""
    plant, gyro, host, pilot, scanner, wire = rig.plant, rig.gyro, rig.host, rig.pilot, rig.scanner, rig.wire
    goal = None
    if pilot is not None:
        commands = [*commands, *pilot.sent]
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
                        step_contact_speed=contact, step_volts=motion[:, 4:6],
                        winding_temp=cols["winding_temp"], battery=cols["battery"])
    board = BoardLog(cols["tick_time"], cols["setpoint"], cols["measured"], cols["pwm"], cols["counts"],
                     cols["tick_cycles"])
    odometry = Odometry(cols["odom_wheel"], cols["odom_velocity"], cols["odom_gyro"],
                        cols["odom_ekf"] if ekf else None, cols["odom_ekf_vel"] if ekf else None,
                        gyro_time=np.array(gyro.times), gyro_rate=np.array(gyro.rates))
    lines = rig.lines
    link = LinkLog(lines.all, lines.events, lines.boots, dict(host.line_counts), _cmd_vel(commands))
    stop_at = stop_time(scenario, wire, lines.events, None if goal is None else goal.reached_s)
    return SimResult(scenario=scenario.name, backend=backend, duration=ran.end_cycle / F_CPU,
                     wall_time=wall, truth=truth, board=board, odometry=odometry, link=link,
                     faults=scenario.faults, fault_at=fault_time(scenario, wire), goal=goal,
                     lockstep=ran.lockstep, stop_at=stop_at, terrain=scenario.terrain,
                     world=_world_log(scenario, plant),
                     lidar=None if scanner is None else LidarLog(scanner.lidar, scanner.scans))



def fault_time(scenario: Scenario, wire: WireSchedule) -> float | None:
    """When the fault figures count from (``SimResult.fault_metrics``): the earliest of
    the faults' ``at`` and of the ``silence`` segments' starts; for a ``link_cut`` or a
    silence, the time at which the last byte that started before it reached the board.
    None when the scenario has neither."""
    triggers: list[tuple[float, bool]] = [(f.at, f.kind == "link_cut") for f in scenario.faults]
    t0 = scenario.segments_start
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
        t0 = scenario.segments_start
        start: float | None = 0.0
        for seg in scenario.segments:
            if _commands_motion(seg):
                start = None
            elif start is None:
                start = _last_byte_before(wire, t0) if seg.kind == "silence" else t0
            t0 += seg.duration
        candidates.append(t0 if start is None else start)
    end_of_segments = scenario.segments_start + sum(seg.duration for seg in scenario.segments)
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
