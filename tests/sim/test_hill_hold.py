"""The hill hold and rollaway on a grade, watched from the plant, on both backends.

A chair parked without a fault holds each wheel at the count it stopped at (PROTOCOL.md,
"Hold and rollaway"). Driven up a 1:12 or a 1:20 grade and stopped, by a zero command
or by the watchdog, its wheels roll less than 2 cm over the next 60 s; on the level it
stands at duty 0. The chassis's own travel is held to that of a chair whose wheels are
locked (a perfect parking brake) plus those 2 cm: the tyres' contact patches deflect
under the grade's pull (0.4 mm on 1:12, tests/plant/test_grip.py).
Pushed harder than the hold can carry (one motor open circuit on 1:12) the chair rolls:
``EVT:ROLLAWAY`` at the first tick at which a wheel is ROLLAWAY_COUNTS (2 cm) off its
count, and the hold keeps braking at HOLD_PWM_MAX. The compiled firmware gives the same bits as the port on
each run.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import thorough
from tests.support.depth import cases
from tests.support.grade import checked_run
from wcdrive.firmware import constants as C
from wcdrive.plant import ChairParams, Plant
from wcdrive.plant.terrain import Terrain
from wcdrive.sim import runner, scenario

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))
ONE_IN_12 = math.degrees(math.atan(1 / 12))     # 4.76 degrees
ONE_IN_20 = math.degrees(math.atan(1 / 20))     # 2.86 degrees
DRIVE_S = 2.0                                   # up the grade at 0.3 m/s, then the stop
HOLD_S = 60.0
STOP_AT = DRIVE_S                               # the drive ends: the stop
METRES_PER_COUNT = 2 * math.pi * ChairParams().wheel_radius / ChairParams().counts_per_rev


def _scenario(tmp: Path, slope: float, stop: str, dead_at: float | None = None,
              duration: float = HOLD_S + 10.0) -> scenario.Scenario:
    """Up a grade of ``slope`` degrees (the floor falls toward -x, the chair faces +x),
    then ``stop``: "zero" (zero commands go on) or "silence" (the watchdog stops it);
    the left motor open circuit from ``dead_at`` s."""
    tail = "cmdvel = [0.0, 0.0]" if stop == "zero" else "silence = true"
    text = (f'name = "hold"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
            f"[world]\nslope_deg = {slope}\ndownhill_heading_deg = 180\n")
    text += f"[[segment]]\ncmdvel = [0.3, 0.0]\nduration = {DRIVE_S}\n"
    text += f"[[segment]]\n{tail}\nduration = {duration}\n"
    if dead_at is not None:
        text += f'[[fault]]\nat = {dead_at}\nkind = "motor_dead"\nside = "left"\n'
    path = tmp / f"hold_{slope:.3f}_{stop}_{dead_at}.toml"
    path.write_text(text)
    return scenario.load(str(path))


@cache
def _run(slope: float, stop: str, backend: str, dead_at: float | None = None) -> runner.SimResult:
    tmp = Path(f"/tmp/wcdrive-hold-{backend}")
    tmp.mkdir(exist_ok=True)
    duration = HOLD_S + 10.0 if dead_at is None else dead_at + 5.0
    return checked_run(_scenario(tmp, slope, stop, dead_at, duration), backend)


def _park_tick(r: runner.SimResult, stop: str) -> int:
    """The tick the chair parks at after the stop (a zero command or the watchdog's
    emergency ramp): the first with both setpoints at zero and both wheels slower than
    BRAKE_DONE_SPEED."""
    t = r.board.tick_time
    rest = (t > STOP_AT) & np.all(r.board.setpoint == 0.0, axis=1)
    speed = np.abs(r.board.measured).max(axis=1)
    return int(np.argmax(rest & (speed < C.BRAKE_DONE_SPEED)))


def _drift(r: runner.SimResult, stop: str) -> tuple[float, float]:
    """(m the wheels rolled, m the chassis moved) at most over HOLD_S after the park."""
    i = _park_tick(r, stop)
    t = r.board.tick_time
    window = (t >= t[i]) & (t <= t[i] + HOLD_S)
    assert t[-1] >= t[i] + HOLD_S
    rolled = np.abs(r.board.counts[window] - r.board.counts[i]).max() * METRES_PER_COUNT
    moved = np.hypot(*(r.truth.pose[window, :2] - r.truth.pose[i, :2]).T).max()
    return float(rolled), float(moved)


@cache
def _locked_slide(slope: float) -> float:
    """m the chassis slides in HOLD_S on a grade of ``slope`` degrees with both wheels locked."""
    plant = Plant(ChairParams(), terrain=Terrain(slope, 180.0))
    plant.set_wheel_locked("left")
    plant.set_wheel_locked("right")
    plant.advance(2000)
    x0, y0, _ = plant.pose
    plant.advance(round(HOLD_S * 1000))
    x, y, _ = plant.pose
    return math.hypot(x - x0, y - y0)


#: Each park runs 70 simulated s (33 s of wall time on simavr); the fast depth runs them
#: on the port (the hold on simavr there: tests/sim/test_grade_limits.py's parks), the
#: thorough depth on simavr too.
@pytest.mark.parametrize(("slope", "stop", "backend"), cases(
    [(ONE_IN_12, "zero"), (ONE_IN_12, "silence"), (ONE_IN_20, "zero"), (ONE_IN_20, "silence")],
    ["1:12-zero", "1:12-silence", "1:20-zero", "1:20-silence"], fast_simavr=[]))
def test_a_chair_parked_on_a_ramp_stays(slope: float, stop: str, backend: str) -> None:
    r = _run(slope, stop, backend)
    if stop == "silence":
        assert any(line == "EVT:WATCHDOG" for _, line in r.link.events)
    assert not any(line.startswith(("EVT:FAULT", "EVT:ROLLAWAY")) for _, line in r.link.events)
    rolled, moved = _drift(r, stop)
    assert rolled <= 0.02, rolled
    assert moved <= _locked_slide(slope) + 0.02, (moved, _locked_slide(slope))
    # the hold pushes uphill (forward, +x) to hold the chair
    assert np.all(r.board.pwm[-20:] > 0) and np.all(r.board.pwm[-20:] <= C.HOLD_PWM_MAX)


@pytest.mark.parametrize("backend", BACKENDS if thorough() else ["port"])
def test_a_chair_parked_on_the_level_stands_at_duty_zero(backend: str) -> None:
    r = _run(0.0, "zero", backend)
    i = _park_tick(r, "zero")
    after = slice(i + 1, None)
    assert np.all(r.board.pwm[after] == 0)
    settled = r.board.tick_time > r.board.tick_time[i] + 1.0
    # still: a wheel resting on a quadrature edge may flicker one count across it
    assert np.all(np.abs(r.board.counts[settled] - r.board.counts[-1]) <= 1)
    # parked below BRAKE_DONE_SPEED, the hold follows the last of the coast (duty 0)
    rolled, moved = _drift(r, "zero")
    assert rolled <= 0.01 and moved < 0.01


DEAD_AT = 8.0      # s: the left motor goes open circuit, the chair held on 1:12 since 2.6 s


#: On simavr (13 simulated s) at the thorough depth; at the fast one the firmware rolls
#: away and brakes at HOLD_PWM_MAX in tests/sim/test_grade_limits.py's 2 s park beyond
#: the hold, on simavr.
@pytest.mark.parametrize("backend", BACKENDS if thorough() else ["port"])
def test_a_push_beyond_the_hold_rolls_away_and_is_braked_hardest(backend: str) -> None:
    """Held on 1:12 after the watchdog, the left motor goes open circuit: the right one
    alone cannot hold the chair (at the current limit it carries 99 N of the grade's
    155 N), and it rolls back. EVT:ROLLAWAY, once, at the first tick a wheel is more
    than ROLLAWAY_COUNTS past where the chair was held; from then on both wheels are
    driven forward (uphill, against the roll) at HOLD_PWM_MAX."""
    r = _run(ONE_IN_12, "silence", backend, dead_at=DEAD_AT)
    rolls = [t for t, line in r.link.events if line == "EVT:ROLLAWAY"]
    assert len(rolls) == 1
    t = r.board.tick_time
    held = int(np.searchsorted(t, DEAD_AT))              # the counts then are within the deadband
    off = np.abs(r.board.counts - r.board.counts[held]).max(axis=1)
    first = int(np.argmax((t > DEAD_AT) & (off > C.ROLLAWAY_COUNTS + 2 * C.HOLD_DEADBAND_COUNTS)))
    assert off[first] > C.ROLLAWAY_COUNTS
    assert rolls[0] <= t[first] + 0.01                    # by the tick it is 2 cm off (lines: 10 ms)
    assert rolls[0] - DEAD_AT < 1.0
    faults = [t_ for t_, line in r.link.events if line.startswith("EVT:FAULT")]
    braking = (t > rolls[0] + 0.01) & (t < (faults[0] if faults else np.inf))
    assert braking.sum() >= 5
    assert np.all(r.board.pwm[braking] == C.HOLD_PWM_MAX)
