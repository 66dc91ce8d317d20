"""A chair that drives on after its watchdog began to stop it is no faulty motor, watched
from the plant, on both backends.

The host falls silent while driving (a link stutter), the watchdog ramps the setpoints
down from zeroed integrators, and the host resumes during the ramp. Rebuilt from zero
the integrals left the duty collapsed: the wheels braked on their own back-EMF (from
1 m/s to under half of it) and went on slowing while the duty climbed back, which the
motor rule took for dead motors: the three pinned cases latched ``FAULT,MOTOR_L``,
``STALLED_ON_GRADE`` and ``FAULT,MOTOR_R``, and 52 of the 180 drives of
``benchmarks/motor_rule.py`` an alarm. A command that drives on takes back what the
integrals held (``resumedIntegral``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import thorough
from tests.support.grade import alarms, checked_run
from wcdrive.plant import ChairParams
from wcdrive.sim import runner, scenario

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))


def _scenario(tmp: Path, speed: float, turn: float, gap: float, slope: float = 0.0,
              heading: float = 0.0) -> scenario.Scenario:
    text = (f'name = "watchdog_resume"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
            f"[world]\nslope_deg = {slope}\ndownhill_heading_deg = {heading}\n"
            f"[[segment]]\ncmdvel = [{speed}, {turn}]\nduration = 8.0\n"
            f"[[segment]]\nsilence = true\nduration = {gap}\n"
            f"[[segment]]\ncmdvel = [{speed}, {turn}]\nduration = 3.0\n")
    path = tmp / "watchdog_resume.toml"
    path.write_text(text)
    return scenario.load(str(path))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("turn", [0.4, 0.0, -0.4])
def test_driving_on_after_a_watchdog_stop_is_no_fault(tmp_path: Path, turn: float, backend: str) -> None:
    r = checked_run(_scenario(tmp_path, 1.0, turn, 0.5), backend)
    events = [line for _, line in r.link.events]
    assert any(line.startswith("EVT:WATCHDOG") for line in events), events
    assert alarms(r) == [], events
    # the plant's wheels keep more than 80 % of the commanded speed through the stutter
    after = r.board.tick_time >= 8.5
    rim = np.abs(r.truth.wheel_speed[after]).mean(axis=1) * ChairParams().wheel_radius
    assert rim.min() > 0.8 * 1.0, rim.min()


@st.composite
def _grounds(draw: st.DrawFn) -> tuple[float, float, float]:
    """(turn, slope, heading): turns on the level, straight up, down or across a slope.
    Turning for seconds on a slope is a false alarm of its own, silence or not
    (docs/safety.md, "Known: turning on a slope")."""
    slope = draw(st.sampled_from([0.0, 2.0, 4.0]))
    if slope == 0.0:
        return draw(st.sampled_from([0.0, 0.2, -0.2, 0.4, -0.4])), 0.0, 0.0
    return 0.0, slope, draw(st.sampled_from([0.0, 90.0, 180.0]))


@settings(max_examples=100 if thorough() else 10, deadline=None)
@given(speed=st.sampled_from([0.5, 1.0, 1.5, 2.0, 2.68]), gap=st.sampled_from([0.5, 0.55, 0.6, 0.7, 0.9]),
       ground=_grounds())
def test_no_alarm_after_any_watchdog_stop_and_resume(tmp_path_factory, speed: float, gap: float,
                                                     ground: tuple[float, float, float]) -> None:
    turn, slope, heading = ground
    tmp = Path(tmp_path_factory.mktemp("resume"))
    r = runner.run(_scenario(tmp, speed, turn, gap, slope, heading))
    assert alarms(r) == [], (speed, turn, gap, slope, heading, r.link.events)
