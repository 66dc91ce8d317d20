"""The safety bounds (docs/safety.md), checked on a run of a fault scenario.

``violations(scenario, result)`` lists, in words, every bound a ``SimResult`` breaks
(empty: the run is safe). By the scenario's first fault (or its ``silence`` segment):

* ``encoder_cut``, ``encoder_reversed``, ``wheel_locked``, ``motor_dead``: an
  ``EVT:FAULT`` line after the fault, both duties 0 to the end, a standstill within
  ``standstill_bound`` of the fault, and a peak speed at most ``PEAK_MARGIN`` above
  the commanded speed;
* ``encoder_noise``: control ticks at most ``MAX_TICK_GAP_MS`` apart, an
  ``EVT:FAULT,ENC_IMPLAUSIBLE_<side>`` line for each noisy side, a standstill, and no
  reset by the hardware watchdog (no ``BOOT:...,WATCHDOG`` line);
* ``link_cut`` and ``silence``: the motors stay powered (braking) until the chair is
  nearly still (``BRAKE_UNTIL_MPS``), and the travel after the last byte is within
  ``stopping_bound``;
* ``reset``: the motors unpowered from the reset until the rebooted firmware's first
  control tick, and a ``BOOT:final_control,EXTERNAL`` line.

``stopping_bound`` is the issue's goal for the distance after the last byte: the
distance at constant speed over the watchdog time, plus the braking distance at
``estop_decel``, plus 0.1 m. Two corrections: the board notices a command at the next
tick and checks its watchdog once a tick, so it fires between ``watchdog_ms`` and
``watchdog_ms`` + 100 ms after the last byte (``WATCHDOG_LATENCY_MS``); and no chair
brakes harder than its motors can, so the
braking distance is at the smaller of ``estop_decel`` and the plant's
``ChairParams.max_braking`` (1.12 m/s^2 at the driver's 13 A: ``estop_decel``'s default
of 15 rad/s^2 at the wheels is 2.29 m/s^2, more than the motors give).

``standstill_bound`` is the issue's 1.0 s after an encoder or wheel fault, or, from a
speed at which the plant cannot stop that fast, what it can: the fault confirmed
(``DETECTION_S``), the braking at ``max_braking`` down to the speed at which the
unpowered motors leave the current limit, and the fading brake of their back-EMF from
there (``FADE_S``, measured on the plant: 0.88 s from 0.5 m/s with duty 0; twice that
for a dead motor, whose wheel does not brake).
"""

from __future__ import annotations

import numpy as np

from wcdrive.avr.timer0 import F_CPU
from wcdrive.plant.faults import Fault
from wcdrive.protocol.spec import real
from wcdrive.sim.result import SimResult
from wcdrive.sim.scenario import Scenario

#: s: the chair stands still this soon after an encoder, wheel or motor fault (the
#: issue's figure; ``standstill_bound`` says when physics allows less).
STANDSTILL_WITHIN_S = 1.0
#: s: a fault is latched at most this long after it starts (3 ticks; the motor fault
#: takes longer and is given ``MOTOR_DETECTION_S``).
DETECTION_S = 0.15
MOTOR_DETECTION_S = 1.2
#: s: from the current-limit speed (0.44 m/s) to standstill with the motors unpowered.
FADE_S = 0.9
#: ms: the watchdog fires this long after ``watchdog_ms`` at the latest (two ticks).
WATCHDOG_LATENCY_MS = 100.0
#: The peak speed after such a fault may exceed the commanded speed by this fraction.
PEAK_MARGIN = 0.10
#: ms: the longest interval between two control ticks under an encoder storm.
MAX_TICK_GAP_MS = 60.0
#: m/s: after a silence, the motors are unpowered only once the chair is this slow.
BRAKE_UNTIL_MPS = 0.1
#: m: the margin of ``stopping_bound``.
STOPPING_MARGIN_M = 0.1
#: The BOOT line's cause after a ``reset`` fault (a DTR pulse: MCUSR's EXTRF).
RESET_CAUSE = "EXTERNAL"

WHEEL_RADIUS = real("WHEEL_RADIUS")
EMERGENCY_DECEL = real("EMERGENCY_DECEL")
WATCHDOG_MS = real("WATCHDOG_MS")


def stopping_bound(speed: float, watchdog_ms: float = WATCHDOG_MS, estop_decel: float = EMERGENCY_DECEL,
                   wheel_radius: float = WHEEL_RADIUS) -> float:
    """m: the most a chair at ``speed`` (m/s) may travel after the last byte: ``speed``
    over the watchdog time and its latency, plus the braking distance at
    ``estop_decel`` (rad/s^2 at the wheels), plus ``STOPPING_MARGIN_M``."""
    decel = estop_decel * wheel_radius
    return (speed * (watchdog_ms + WATCHDOG_LATENCY_MS) / 1000.0 + speed * speed / (2.0 * decel)
            + STOPPING_MARGIN_M)


def standstill_bound(speed: float, max_braking: float, limit_speed: float, kind: str = "") -> float:
    """s: how soon after a fault a chair at ``speed`` (m/s) must stand still (module
    docstring): ``STANDSTILL_WITHIN_S``, or the fastest the plant can do."""
    detect = MOTOR_DETECTION_S if kind == "motor_dead" else DETECTION_S
    fade = 2 * FADE_S if kind == "motor_dead" else FADE_S
    physics = detect + max(0.0, speed - limit_speed) / max_braking + fade
    return max(STANDSTILL_WITHIN_S, physics)


def commanded_speed(scenario: Scenario, t: float) -> float:
    """m/s: the linear speed the scenario's host commands at time ``t`` (the wheel
    speeds' mean for a ``wheel`` segment; 0 for stop, silence and PPM)."""
    t0 = scenario.segments_start
    for seg in scenario.segments:
        if t < t0 + seg.duration:
            if seg.kind == "cmdvel":
                return abs(seg.values[0])
            if seg.kind == "wheel":
                return abs(seg.values[0] + seg.values[1]) / 2.0 * WHEEL_RADIUS
            return 0.0
        t0 += seg.duration
    return 0.0


def trigger(scenario: Scenario) -> tuple[str, Fault | None]:
    """What the fault figures of a run of ``scenario`` count from: the kind of its
    earliest fault, or "silence" when a ``silence`` segment comes first, with that fault
    (None for a silence); ("none", None) when it has neither."""
    found: list[tuple[float, str, Fault | None]] = [(f.at, f.kind, f) for f in scenario.faults]
    t0 = scenario.segments_start
    for seg in scenario.segments:
        if seg.kind == "silence":
            found.append((t0, "silence", None))
            break
        t0 += seg.duration
    if not found:
        return "none", None
    _, kind, fault = min(found, key=lambda x: x[0])
    return kind, fault


def speed_at(result: SimResult, t: float) -> float:
    """m/s: the chair's true speed at time ``t`` (the physics step ending there)."""
    truth = result.truth
    if truth.step_time.size == 0:
        return 0.0
    i = min(int(np.searchsorted(truth.step_time, t - 1e-12)), truth.step_time.size - 1)
    return float(truth.step_speed[i])


def violations(scenario: Scenario, result: SimResult) -> list[str]:
    """Every safety bound of the module docstring that ``result`` (a run of
    ``scenario``) breaks, in words; empty when it keeps them all."""
    m = result.fault_metrics()
    at = m["fault_at_s"]
    if at is None:
        return []
    out: list[str] = []
    kind, _ = trigger(scenario)
    events = [(t, line) for t, line in result.link.events if t >= at - 1e-9]
    if kind in ("encoder_cut", "encoder_reversed", "wheel_locked", "motor_dead"):
        if not any(line.startswith("EVT:FAULT,") for _, line in events):
            out.append(f"no EVT:FAULT line after the {kind} at {at} s")
        if m["pwm_zero_after_fault_s"] is None:
            out.append("the motors are still powered at the end")
        still = m["standstill_after_fault_s"]
        commanded = commanded_speed(scenario, at)
        chair = scenario.params()
        within = standstill_bound(commanded, chair.max_braking, chair.current_limit_speed, kind)
        if still is None or still > within:
            out.append(f"no standstill within {within:.2f} s of the fault "
                       f"(standstill after {_s(still)})")
        peak = m["peak_speed_after_fault_mps"]
        if peak is not None and peak > commanded * (1.0 + PEAK_MARGIN):
            out.append(f"peak speed {peak:.3f} m/s after the fault exceeds the commanded "
                       f"{commanded:.3f} m/s by more than {PEAK_MARGIN:.0%}")
    elif kind == "encoder_noise":
        gap = m["max_tick_gap_ms"]
        if gap is not None and gap > MAX_TICK_GAP_MS:
            out.append(f"control ticks {gap:.1f} ms apart (at most {MAX_TICK_GAP_MS:g} ms)")
        sides = {f.side for f in scenario.faults if f.kind == "encoder_noise"}
        for side in ("left", "right"):
            if side in sides or "both" in sides:
                name = f"EVT:FAULT,ENC_IMPLAUSIBLE_{side[0].upper()}"
                if not any(line == name for _, line in events):
                    out.append(f"no {name} line")
        if m["standstill_after_fault_s"] is None:
            out.append("the chair never stops")
        if any(line.endswith(",WATCHDOG") for _, line in result.link.boots):
            out.append("the hardware watchdog reset the board")
    elif kind in ("link_cut", "silence"):
        watchdog = scenario.board_params.get("watchdog_ms", WATCHDOG_MS)
        decel = scenario.board_params.get("estop_decel", EMERGENCY_DECEL)
        speed = speed_at(result, at)
        chair = scenario.params()
        bound = stopping_bound(speed, watchdog, min(decel, chair.max_braking / chair.wheel_radius),
                               chair.wheel_radius)
        travel = m["travel_after_fault_m"] or 0.0
        if travel > bound:
            out.append(f"travelled {travel:.3f} m after the last byte, more than the bound "
                       f"{bound:.3f} m (at {speed:.3f} m/s, watchdog {watchdog:g} ms)")
        zero = m["pwm_zero_after_fault_s"]
        if zero is None:
            out.append("the motors are still powered at the end")
        else:
            coasting = speed_at(result, at + zero)
            if coasting > BRAKE_UNTIL_MPS:
                out.append(f"the motors were unpowered at {coasting:.3f} m/s, not braking the chair "
                           f"to {BRAKE_UNTIL_MPS} m/s")
        if m["standstill_after_fault_s"] is None:
            out.append("the chair never stops")
    elif kind == "reset":
        ticks, truth = result.board.tick_cycles, result.truth
        after = ticks[ticks > round(at * F_CPU)]
        first_tick = after[0] / F_CPU if after.size else result.duration
        window = (truth.step_time > at + 1e-9) & (truth.step_time <= first_tick)
        if np.any(truth.step_volts[window] != 0.0):
            out.append("the motors were powered between the reset and the first control tick after it")
        boot = f"BOOT:final_control,{RESET_CAUSE}"
        if not any(line == boot and t >= at - 1e-9 for t, line in result.link.boots):
            out.append(f"no {boot} line after the reset")
    return out


def _s(v: float | None) -> str:
    return "never" if v is None else f"{v:.3f} s"
