"""The motors' currents in a lock-step trace: a stand against a wall, as the firmware's
inputs show it (``held_against_a_wall``), and the current senses about it.

A trace's encoders are scripted, not driven by the duty, so a wheel held at its current
limit is drawn as what the board reads: both encoders without an edge for a while
(``stand_still``); both current senses at 11.5 to 14 A, forward or back, from just
before it (the ADC interrupt after a tick reads them); the stall clock set within 0.1 s
of STALL_TIMEOUT once or twice inside it, with the chair driving into the wall the
currents' way then (``pushing``, ``Trace.pokes``: a trace of a few seconds cannot run
the clock for 15 s, and its random commands seldom drive while its encoders stand); and
the senses changed at random times besides (``current_changes``): mostly about
STALL_CURRENT either way, some small, a tenth at a failed sense's volts (past
CURRENT_SENSE_MAX). Half of them set ``stall_timeout`` first, in range (1, 14.95, 15.5,
60 s) or out (0.5, 61).
"""

from __future__ import annotations

import numpy as np

from wcdrive.boards.current_sense import current_millivolts
from wcdrive.hil.trace_base import Trace, spaced
from wcdrive.plant.encoders import EdgeTrain

__all__ = ["CURRENT_SPACING_S", "current_changes", "held_against_a_wall", "pushing", "stand_still"]

#: The least time between two changes of one current sense (s): more than a tick, so
#: that the ADC interrupt after a tick reads one value or the other.
CURRENT_SPACING_S = 0.06


def held_against_a_wall(rng: np.random.Generator, trace: Trace) -> None:
    """Puts a stand against a wall into ``trace`` (the module docstring): from a time in
    its first 70 %, 0.3 to 1.5 s long."""
    duration = trace.duration
    start = round(float(rng.uniform(0.3, max(0.31, 0.7 * duration))), 4)
    stop = round(min(duration - 0.05, start + float(rng.uniform(0.3, 1.5))), 4)
    trace.encoders = {side: stand_still(train, start, stop) for side, train in trace.encoders.items()}
    before = max(0.0, round(start - 0.06, 4))
    way = 1.0 if rng.random() < 0.5 else -1.0        # forward or back, the currents with it
    held = [(before, side, current_millivolts(way * float(rng.uniform(11.5, 14.0))))
            for side in ("left", "right")]
    others = [c for c in current_changes(rng, duration)
              if abs(c[0] - before) >= CURRENT_SPACING_S]
    trace.currents = sorted(held + others)
    clock = [(round(float(rng.uniform(start, stop)), 4), pushing(rng, way))
             for _ in range(int(rng.integers(1, 3)))]
    trace.pokes = sorted(trace.pokes + clock, key=lambda p: p[0])
    # the stall timeout set, in range and out, in half of them: from the start (the
    # clock set near 15 s then times out or not by it)
    if rng.random() < 0.5:
        value = float(rng.choice([0.5, 1.0, 14.95, 15.5, 60.0, 61.0]))
        trace.serial.insert(0, (0.01, b"set:stall_timeout=%g\n" % value))


def pushing(rng: np.random.Generator, way: float) -> dict[str, float | int]:
    """A chair driving into the wall at a tick's entry: both wheels' targets and setpoints
    ``way`` (1 to 4 rad/s), their duties the last tick applied that way (42 to 120: the
    PID's, at or past FAULT_STALL_PWM_STANDING), and the stall clock nine times in ten
    within 0.1 s of STALL_TIMEOUT (else at 0)."""
    speed = way * round(float(rng.uniform(1.0, 4.0)), 3)
    duty = int(rng.integers(42, 121))
    way = 1 if speed > 0.0 else 0
    clock = round(float(rng.uniform(14.9, 14.99)), 3) if rng.random() < 0.9 else 0.0
    return {"stallTime": clock, "targetL": speed, "targetR": speed, "setpointL": speed, "setpointR": speed,
            "pwmL": duty, "pwmR": duty, "dirL": way, "dirR": way}


def stand_still(train: EdgeTrain, start: float, stop: float) -> EdgeTrain:
    """``train`` without its edges in [start, stop]: the wheel stands there (the edges
    after it go on from where the motion would have been)."""
    keep = (train.times < start) | (train.times > stop)
    return EdgeTrain(train.times[keep], train.states[keep], train.start_count, train.end_count)


def current_changes(rng: np.random.Generator, duration: float) -> list[tuple[float, str, int]]:
    """One to three changes of each motor's current sense over ``duration`` s, as (s,
    side, mV, ``current_millivolts``), each side's at least ``CURRENT_SPACING_S`` apart:
    seven in ten between 9 and 14 A either way (about STALL_CURRENT), two small (under
    5 A), one anywhere from 0 to 5 V (past CURRENT_SENSE_MAX: a failed sense)."""
    out: list[tuple[float, str, int]] = []
    for side in ("left", "right"):
        changes: list[tuple[float, int]] = []
        for _ in range(int(rng.integers(1, 4))):
            at = round(float(rng.uniform(0.05, max(0.06, duration - 0.05))), 4)
            kind = rng.random()
            sign = 1.0 if rng.random() < 0.5 else -1.0
            if kind < 0.7:
                mv = current_millivolts(sign * float(rng.uniform(9.0, 14.0)))
            elif kind < 0.9:
                mv = current_millivolts(sign * float(rng.uniform(0.0, 5.0)))
            else:
                mv = int(rng.integers(0, 5001))
            changes.append((at, mv))
        out += [(at, side, mv) for at, mv in spaced(changes, CURRENT_SPACING_S)]
    return sorted(out)
