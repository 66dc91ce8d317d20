"""The chair's limits on a grade are not faults, watched from the plant, on both backends.

Beyond what the motors can climb, both wheels strain at once: ``EVT:STALLED_ON_GRADE``
and the hold, never a latched ``MOTOR`` or ``ENC_REVERSED`` fault and unpowered motors.
Downhill beyond what they can brake, ``EVT:OVERSPEED`` within 0.2 s of the plant's wheel
running away from its setpoint under braking, and the hold braking hardest. A dragged
wheel in a spin faster than the chair can follow is the same limit (PROTOCOL.md, "The
chair's limits"). Each run on simavr gives the same bits as the port.
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from tests.support.depth import cases
from tests.support.grade import alarms, checked_run
from wcdrive.firmware import constants as C
from wcdrive.sim import runner, scenario

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))
ONE_IN_8 = math.degrees(math.atan(1 / 8))       # 7.13 degrees, a kerb cut
ONE_IN_12 = math.degrees(math.atan(1 / 12))     # 4.76 degrees


def _events(r: runner.SimResult, prefix: str) -> list[float]:
    return [t for t, line in r.link.events if line.startswith(prefix)]


@cache
def _run(name: str, slope: float, downhill: float, segments: tuple[tuple[str, str, float], ...],
         chair: str, backend: str) -> runner.SimResult:
    text = (f'name = "{name}"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
            f"[world]\nslope_deg = {slope}\ndownhill_heading_deg = {downhill}\n")
    if chair:
        text += f"[chair]\n{chair}\n"
    for kind, value, duration in segments:
        text += f"[[segment]]\n{kind} = {value}\nduration = {duration}\n"
    tmp = Path(f"/tmp/wcdrive-grade-{backend}")
    tmp.mkdir(exist_ok=True)
    path = tmp / f"{name}.toml"
    path.write_text(text)
    return checked_run(scenario.load(str(path)), backend)


UP = (("cmdvel", "[0.5, 0.0]", 3.0), ("cmdvel", "[0.0, 0.0]", 2.0))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("slope", "chair"), [(ONE_IN_8, ""), (ONE_IN_12, "occupant_mass = 150.0")],
                         ids=["1:8", "1:12-150kg"])
def test_a_climb_beyond_the_motors_stalls_and_holds_without_a_fault(slope: float, chair: str,
                                                                    backend: str) -> None:
    r = _run(f"climb_{slope:.2f}_{bool(chair)}", slope, 180.0, UP, chair, backend)
    assert _events(r, "EVT:STALLED_ON_GRADE")
    assert not _events(r, "EVT:FAULT")
    # it stalled while driving up, and the plant's chair was then slower than asked
    first = _events(r, "EVT:STALLED_ON_GRADE")[0]
    assert first < 3.5
    t = r.board.tick_time
    i = int(np.searchsorted(t, first))
    assert np.all(r.truth.wheel_speed[i] < 0.8 * (0.5 / C.WHEEL_RADIUS))
    # after the stop the motors hold (or brake) the chair: never unpowered while it moves
    after = (t > 3.6) & (np.abs(r.truth.wheel_speed).max(axis=1) > 0.5)
    assert np.all(np.abs(r.board.pwm[after]) > 0)


DOWN = (("cmdvel", "[1.0, 0.0]", 3.0),)


@pytest.mark.parametrize("backend", BACKENDS)
def test_downhill_beyond_the_brakes_is_an_overspeed_within_0_2_s(backend: str) -> None:
    """Then the hold brakes hardest; beyond what it carries, the held wheels' runaway may
    latch ENC_REVERSED later (a known limit: docs/safety.md), never before the event."""
    r = _run("down_10", 10.0, 0.0, DOWN, "", backend)
    overs = _events(r, "EVT:OVERSPEED")
    assert overs
    faults = _events(r, "EVT:FAULT")
    assert all(f > overs[0] + 0.1 for f in faults)
    assert all(line.startswith("EVT:FAULT,ENC_REVERSED") for _, line in r.link.events
               if line.startswith("EVT:FAULT"))
    t = r.board.tick_time
    true_speed = r.truth.wheel_speed.min(axis=1)          # both wheels run away forward
    setpoint = r.board.setpoint.max(axis=1)
    braking = r.board.pwm.max(axis=1) <= -C.OVERSPEED_PWM
    rising = np.r_[False, np.diff(true_speed) > 0]
    driving = t >= t[int(np.argmax(setpoint > 0.0))]        # not the hold before the drive
    physics = (true_speed > setpoint + C.OVERSPEED_MARGIN) & braking & rising & driving
    assert physics.any()
    # judged tick to tick: the tick that sent the event (its line reaches the host a
    # couple of ms later) against the first tick the physics showed it
    sent = t[int(np.searchsorted(t, overs[0], side="right")) - 1]
    assert sent - t[int(np.argmax(physics))] <= 0.2 + 1e-9
    # from the event on, the hold brakes hardest
    j = int(np.searchsorted(t, overs[0] + 0.06))
    assert np.all(r.board.pwm[j:j + 2] == -C.HOLD_PWM_MAX)


SPIN = (("cmdvel", "[0.0, 3.0]", 2.0), ("wheel", "[17.0, -17.0]", 3.0), ("cmdvel", "[0.0, 0.0]", 1.0))


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_spin_the_chair_cannot_follow_is_its_limit_not_a_reversed_encoder(backend: str) -> None:
    """The left wheel, at full reverse and its current limit, is dragged forward by the
    chassis while the right one strains short of +17 rad/s: not ENC_REVERSED_L."""
    r = _run("spin", 0.0, 0.0, SPIN, "", backend)
    assert not _events(r, "EVT:FAULT")
    assert _events(r, "EVT:STALLED_ON_GRADE")


@pytest.mark.parametrize("backend", BACKENDS)
def test_parked_from_power_on_beyond_the_hold_rolls_away_braked_hardest(backend: str) -> None:
    """Held from the first tick; beyond what the hold carries the chair rolls:
    EVT:ROLLAWAY and the hardest hold, until the held wheels' runaway (speeding up while
    braked) latches ENC_REVERSED, as a reversed encoder would (a known limit:
    docs/safety.md)."""
    r = _run("park_10", 10.0, 180.0, (("cmdvel", "[0.0, 0.0]", 2.0),), "", backend)
    assert not _events(r, "EVT:OVERSPEED")
    rolls = _events(r, "EVT:ROLLAWAY")
    assert len(rolls) == 1
    faults = _events(r, "EVT:FAULT,ENC_REVERSED")
    assert faults and faults[0] > rolls[0]
    t = r.board.tick_time
    # held from the first tick: the hold's duty, never the PID's
    assert np.all(r.board.pwm[t <= rolls[0]] <= C.HOLD_PWM_MAX)
    # up to the tick before the one that latched the fault (its line comes after it)
    between = (t > rolls[0] + 0.06) & (t < faults[0] - C.CONTROL_PERIOD_MS / 1000)
    assert between.any() and np.all(r.board.pwm[between] == C.HOLD_PWM_MAX)


ONE_IN_20 = math.degrees(math.atan(1 / 20))     # 2.86 degrees


@pytest.mark.parametrize(("slope", "speed", "backend"), cases(
    [(ONE_IN_20, 0.5), (ONE_IN_12, 0.5), (ONE_IN_12, 1.0)], ["1:20-0.5", "1:12-0.5", "1:12-1.0"],
    fast_simavr=[]))
def test_a_stop_climbing_comes_to_rest_and_stays(slope: float, speed: float, backend: str) -> None:
    """Climbing, the stop command brings the chair to rest within the level floor's
    stopping distance from the same speed (the grade only helps it stop; scaled by the
    square of the speeds at the stop where the chair climbed faster), and it stays
    there: the integral that carried it up does not carry it on past the stop. (On 1:12
    the default chair crawls, near its rated grade: the stop must still come within the
    bound.)"""
    segments = (("cmdvel", f"[{speed}, 0.0]", 4.0), ("cmdvel", "[0.0, 0.0]", 8.0))
    climb = _run(f"stop_up_{slope:.2f}_{speed}", slope, 180.0, segments, "", backend)
    up = climb.stop_metrics()
    level = _run(f"stop_level_{speed}", 0.0, 180.0, segments, "", backend).stop_metrics()
    assert not alarms(climb)
    assert up["stopping_distance_m"] is not None and level["stopping_distance_m"] is not None
    assert up["max_speed_after_stop_mps"] is not None and level["max_speed_after_stop_mps"] is not None
    scale = (up["max_speed_after_stop_mps"] / level["max_speed_after_stop_mps"]) ** 2
    assert up["stopping_distance_m"] <= level["stopping_distance_m"] * max(1.0, scale)
    assert up["drift_parked_m"] is not None and up["drift_parked_m"] <= 0.02


#: Both speeds on the port; on simavr 1.0 m/s at the fast depth (the climbing stop's
#: level run above, so the same run), both at the thorough one.
@pytest.mark.parametrize(("speed", "backend"), cases([(0.5,), (1.0,)], ["0.5", "1.0"], fast_simavr=["1.0"]))
def test_a_stop_on_the_level_rests_within_a_second_of_the_setpoint(speed: float, backend: str) -> None:
    """The setpoint ramps to zero at ACCEL_MAX; the chair, lagging it, comes to rest
    within a second more: an integral left from the drive does not carry it on."""
    segments = (("cmdvel", f"[{speed}, 0.0]", 4.0), ("cmdvel", "[0.0, 0.0]", 8.0))
    stop = _run(f"stop_level_{speed}", 0.0, 180.0, segments, "", backend).stop_metrics()
    ramp = speed / C.WHEEL_RADIUS / C.ACCEL_MAX
    assert stop["stopping_time_s"] is not None and stop["stopping_time_s"] <= ramp + 1.0


@pytest.mark.parametrize("backend", ("port", pytest.param("simavr", marks=[pytest.mark.simavr,
                                                                         pytest.mark.thorough])))
def test_a_stop_from_top_speed_down_1_in_12_is_no_overspeed(backend: str) -> None:
    """Down 1:12 at the full-speed command (2.64 m/s), then a stop: the chair, braked at
    the driver's limit, slows slowly (about 0.13 rad/s a tick, the measured speed
    swinging by up to 0.3 rad/s tick to tick) and comes to rest; no OVERSPEED, no other
    alarm (a one-tick gain rule sent OVERSPEED 0.6 s into this stop)."""
    segments = (("cmdvel", "[2.68, 0.0]", 8.0), ("cmdvel", "[0.0, 0.0]", 10.0))
    r = _run("stop_top_down_1in12", ONE_IN_12, 0.0, segments, "", backend)
    assert not alarms(r)
    stop = r.stop_metrics()
    assert stop["max_speed_after_stop_mps"] is not None and stop["max_speed_after_stop_mps"] > 2.5
    assert stop["drift_parked_m"] is not None and stop["drift_parked_m"] <= 0.02
