"""A run held to its scenario's ``[expect]`` table (``wcdrive.sim.expect``):
``check(scenario, result)`` lists the misses, each naming the scenario, the backend,
the figure (or event kind), the bound and the value; empty: the run keeps the contract.
A scenario without the table is one miss (``wcdrive sim --check``).

``evaluate`` is the robot-neutral core: a table against a run's figures (a name -> value
mapping) and its ``EVT:`` lines; Eddie's runs come in through it
(``wcdrive.eddie.runner.figures``), without events, anchors or named bounds.

The named bounds, from the scenario and the run (docs/safety.md):

* ``standstill_bound``: ``wcdrive.sim.safety.standstill_bound`` at the speed the host
  commanded when the first fault came, for that fault's kind;
* ``stopping_bound``: ``wcdrive.sim.safety.stopping_bound`` at the chair's true speed
  when the last byte reached the board (``fault_at_s``), with the scenario's
  ``watchdog_ms`` and the gentler of its ``estop_decel`` and the motors' braking limit;
* ``terminal_speed``: the back-EMF terminal speed of the chair, its motors shorted,
  rolling down the steepest grade of the floor (the faster of facing up and down; the
  hand figure of ``tests/plant/test_terrain.py``), or the fastest linear speed the host
  commands, whichever is higher: gravity must not carry the chair faster than that.

The anchors of an event's window (``wcdrive.sim.expect.ANCHORS``): ``stall`` is the
first physics step before the last stop at which the chair, having moved, is slower
than ``STANDSTILL_SPEED``; ``runaway`` the first control tick at which both wheels turn
``OVERSPEED_MARGIN`` or more beyond their setpoints, the way of them (or with a zero
setpoint), while braked at ``OVERSPEED_PWM`` or more against that motion (the plant's
side of the board's ``EVT:OVERSPEED`` rule, PROTOCOL.md "The chair's limits").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from wcdrive.firmware import constants as C
from wcdrive.plant.params import ChairParams, G
from wcdrive.sim import safety
from wcdrive.sim.expect import Bound, Expect, is_alarm, matches
from wcdrive.sim.result import STANDSTILL_SPEED, SimResult
from wcdrive.sim.scenario import Scenario


@dataclass(frozen=True)
class Miss:
    """One promise a run did not keep: where (scenario, backend), what (a figure, an
    event kind, ``[expect]``, ``safety``) and how, in words."""

    scenario: str
    backend: str
    what: str
    detail: str

    def __str__(self) -> str:
        return f"{self.scenario} ({self.backend}): {self.what}: {self.detail}"


#: m/s: the true speed above which the chair is moving (``first_motion_s``).
MOVING_MPS = 0.05


def figures(result: SimResult) -> dict[str, object]:
    """The figures a Mega run's bounds name: ``SimResult.metrics``, ``max_speed_mps``
    (the chair's largest true speed over the run) and ``first_motion_s`` (when its true
    speed first passed ``MOVING_MPS``; None: never)."""
    out = result.metrics()
    speed = result.truth.step_speed
    out["max_speed_mps"] = float(speed.max()) if speed.size else 0.0
    moving = np.flatnonzero(speed > MOVING_MPS)
    out["first_motion_s"] = float(result.truth.step_time[moving[0]]) if moving.size else None
    return out


def check(scenario: Scenario, result: SimResult) -> list[Miss]:
    """The misses of ``result`` (a run of ``scenario``) against ``scenario.expect``
    (module docstring); one miss when the scenario has no ``[expect]`` table."""
    name, backend = scenario.name, result.backend
    expect = scenario.expect
    if expect is None:
        return [Miss(name, backend, "[expect]", "the scenario has no [expect] table: nothing to check")]
    values = figures(result)
    anchors = {a: anchor(a, result) for a in ("start", "fault", "stop", "stall", "runaway")}
    named = {n: named_bound(n, scenario, result) for n in ("standstill_bound", "stopping_bound",
                                                            "terminal_speed")}
    misses = evaluate(expect, values, result.link.events, name=name, backend=backend, anchors=anchors,
                      named=named, host_end_s=host_end(scenario, result))
    for stop in expect.stops:
        moved = dataclasses.replace(result, stop_at=stop.at_s).stop_metrics(stop.parked_s)
        for bound in stop.bounds:
            miss = _held(bound, moved.get(bound.figure), named)
            if miss:
                misses.append(Miss(name, backend, f"stop at {stop.at_s:g} s: {bound.figure}", miss))
    if backend == "simavr" and result.firmware_differences != 0:
        misses.append(Miss(name, backend, "firmware_differences",
                           f"bound = 0, got {result.firmware_differences}"))
    if expect.safety:
        misses += [Miss(name, backend, "safety", v) for v in safety.violations(scenario, result)]
    return misses


def evaluate(expect: Expect, values: Mapping[str, object], events: list[tuple[float, str]] | None, *,
             name: str, backend: str, anchors: Mapping[str, float | None] | None = None,
             named: Mapping[str, float | None] | None = None, host_end_s: float = math.inf) -> list[Miss]:
    """The misses of a run's figures ``values`` and ``EVT:`` lines ``events`` ((s, line);
    None: the robot reports none) against ``expect``'s events and figure bounds (not its
    ``[[expect.stop]]``, nor ``safety``: ``check`` adds those). ``anchors``: the times the
    event windows count from; ``named``: the named bounds' values; ``host_end_s``: the
    host's last command (a ``WATCHDOG`` after it, or after another alarm, is not an
    alarm)."""
    anchors, named = anchors or {"start": 0.0}, named or {}
    out: list[Miss] = []
    if events is None:
        if expect.listed():
            out.append(Miss(name, backend, "events", "this robot reports no events to check"))
    else:
        bodies = [(t, line.removeprefix("EVT:")) for t, line in events]
        for kind in expect.events:
            if not any(matches(kind, b) for _, b in bodies):
                out.append(Miss(name, backend, kind, f"expected EVT:{kind}, got {_kinds(bodies)}"))
        for w in expect.windows:
            at = anchors.get(w.from_)
            if at is None:
                out.append(Miss(name, backend, w.kind, f"expected EVT:{w.kind} from the {w.from_}, "
                                                       f"but the run has no {w.from_}"))
                continue
            opens = at + w.after_s
            closes = math.inf if w.within_s is None else opens + w.within_s
            seen = [t for t, b in bodies if matches(w.kind, b)]
            if not any(opens - 1e-9 <= t <= closes + 1e-9 for t in seen):
                window = f"{opens:.3f} s .. " + ("the end" if closes == math.inf else f"{closes:.3f} s")
                got = ", ".join(f"{t:.3f} s" for t in seen) or "none"
                out.append(Miss(name, backend, w.kind, f"expected EVT:{w.kind} within {window} "
                                                       f"({w.from_} at {at:.3f} s), got {got}"))
        listed = expect.listed()
        first = min((t for t, b in bodies if is_alarm(b) and not matches("WATCHDOG", b)), default=math.inf)
        for t, body in bodies:
            if not is_alarm(body) or any(matches(k, body) for k in listed):
                continue
            if matches("WATCHDOG", body) and (t > host_end_s or t > first):
                continue
            out.append(Miss(name, backend, body.split(",")[0], f"unexpected alarm EVT:{body} at {t:.3f} s"))
    for bound in expect.bounds:
        if bound.figure == "firmware_differences" and backend != "simavr":
            continue
        miss = _held(bound, values.get(bound.figure), named)
        if miss:
            out.append(Miss(name, backend, bound.figure, miss))
    return out


def _held(bound: Bound, value: object, named: Mapping[str, float | None]) -> str:
    """Empty when ``value`` keeps ``bound``, else the miss in words."""
    low, high = (named.get(b) if isinstance(b, str) else b for b in (bound.low, bound.high))
    want = bound.describe(low, high)
    if (isinstance(bound.low, str) and low is None) or (isinstance(bound.high, str) and high is None):
        return f"bound {want}: the bound does not apply to this run, got {_value(value)}"
    if value is None or isinstance(value, (list, dict, str)):
        return f"bound {want}, got {_value(value)}"
    if bound.equals is not None:
        ok = value == bound.equals if isinstance(bound.equals, bool) else \
            (not isinstance(value, bool) and float(value) == bound.equals)  # type: ignore[arg-type]
    else:
        v = float(value)  # type: ignore[arg-type]
        ok = (low is None or v >= low) and (high is None or v <= high)
    return "" if ok else f"bound {want}, got {_value(value)}"


def _value(value: object) -> str:
    if value is None:
        return "none (the run does not have it)"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _kinds(bodies: list[tuple[float, str]]) -> str:
    return ", ".join(f"{b} at {t:.3f} s" for t, b in bodies if is_alarm(b)) or "no alarm"


def host_end(scenario: Scenario, result: SimResult) -> float:
    """s: the host's last command: an open-loop scenario's closing stop, a closed-loop
    one's goal (the end of the run if it never got there)."""
    if scenario.closed_loop:
        reached = None if result.goal is None else result.goal.reached_s
        return result.duration if reached is None else reached
    return scenario.host_commands()[-1][0]


def anchor(name: str, result: SimResult) -> float | None:
    """s: when an event window's anchor (module docstring) came in ``result``; None:
    never."""
    if name == "start":
        return 0.0
    if name == "fault":
        return result.fault_at
    if name == "stop":
        return result.stop_at
    if name == "stall":
        t, speed = result.truth.step_time, result.truth.step_speed
        end = result.stop_at if result.stop_at is not None else math.inf
        moved = np.flatnonzero(speed >= STANDSTILL_SPEED)
        if not moved.size:
            return None
        slow = np.flatnonzero((np.arange(t.size) > moved[0]) & (speed < STANDSTILL_SPEED) & (t < end))
        return float(t[slow[0]]) if slow.size else None
    if name == "runaway":
        board, true = result.board, result.truth.wheel_speed
        sp, pwm = board.setpoint, board.pwm
        way = np.where(sp != 0.0, np.sign(sp), np.sign(true))
        beyond = (true * way >= np.abs(sp) + C.OVERSPEED_MARGIN) & (np.sign(true) == way)
        braked = -pwm * way >= C.OVERSPEED_PWM
        hit = np.flatnonzero(np.all(beyond & braked, axis=1))
        return float(board.tick_time[hit[0]]) if hit.size else None
    raise ValueError(f"no anchor {name!r}")


def named_bound(name: str, scenario: Scenario, result: SimResult) -> float | None:
    """The value of a named bound (module docstring) for a run of ``scenario``; None
    where it does not apply (no fault, no last byte)."""
    chair = scenario.params()
    if name == "terminal_speed":
        return max(terminal_speed(chair, _steepest(scenario)), _fastest_command(scenario))
    at = result.fault_at
    if at is None:
        return None
    if name == "standstill_bound":
        kind, _ = safety.trigger(scenario)
        return safety.standstill_bound(safety.commanded_speed(scenario, at), chair.max_braking,
                                       chair.current_limit_speed, kind)
    if name == "stopping_bound":
        watchdog = scenario.board_params.get("watchdog_ms", safety.WATCHDOG_MS)
        decel = scenario.board_params.get("estop_decel", safety.EMERGENCY_DECEL)
        return safety.stopping_bound(safety.speed_at(result, at), watchdog,
                                     min(decel, chair.max_braking / chair.wheel_radius), chair.wheel_radius)
    raise ValueError(f"no named bound {name!r}")


def terminal_speed(chair: ChairParams, slope_deg: float) -> float:
    """m/s: how fast the chair rolls down a grade of ``slope_deg`` with both motors
    shorted (duty 0), steady: ``r^2 (m g sin t - rolling) / (2 (k2 + b))``, ``k2 = G^2
    eff Ke^2 / R_a``; the faster of facing up and down; 0 on the level."""
    t = math.radians(abs(slope_deg))
    ke = chair.motor_constant
    k2 = chair.gear_ratio ** 2 * chair.gear_efficiency * ke ** 2 / chair.armature_resistance
    best = 0.0
    for facing in (0.0, math.pi):
        drive, caster = chair.grade_loads(t, facing)
        rolling = 2.0 * chair.rolling_resistance * drive + 2.0 * chair.caster_rolling_resistance * caster
        pull = chair.mass * G * math.sin(t) - rolling
        best = max(best, chair.wheel_radius ** 2 * pull / (2.0 * (k2 + chair.viscous_friction)))
    return best


def _steepest(scenario: Scenario) -> float:
    terrain = scenario.terrain
    return max(abs(g) for g in (terrain.slope_deg, *(r.slope_deg for r in terrain.ramps)))


def _fastest_command(scenario: Scenario) -> float:
    speeds = [abs(s.values[0]) for s in scenario.segments if s.kind == "cmdvel"]
    speeds += [abs(s.values[0] + s.values[1]) / 2.0 * chair_radius(scenario)
               for s in scenario.segments if s.kind == "wheel"]
    if scenario.path is not None:
        speeds.append(scenario.follow.speed)
    return max(speeds, default=0.0)


def chair_radius(scenario: Scenario) -> float:
    """m: the drive wheels' radius of the scenario's chair."""
    return scenario.params().wheel_radius
