"""A host that resumes its stream after the watchdog stopped the chair neither drives it
on nor trips a fault, watched from the plant, on both backends.

The host falls silent while driving (a link stutter), the watchdog ramps the setpoints
down from zeroed integrators, and the host resumes during the ramp. Since "Neutral
before motion" (docs/safety.md) the board refuses the resumed command (``ERR:neutral``,
``EVT:NOT_NEUTRAL``) until a neutral one: the chair brakes to rest and stays. Before
that the board drove on, and a second defect showed. Rebuilt from zero
the integrals left the duty collapsed: the wheels braked on their own back-EMF (from
1 m/s to under half of it) and went on slowing while the duty climbed back, which the
motor rule took for dead motors: the three pinned cases latched ``FAULT,MOTOR_L``,
``STALLED_ON_GRADE`` and ``FAULT,MOTOR_R``, and 52 of the 180 drives of
``benchmarks/motor_rule.py`` an alarm. A command that drives on takes back what the
integrals held (``resumedIntegral``); it still does where a command may drive on
during an emergency ramp (a watchdog that fired after a stop command).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import thorough
from tests.support.depth import cases
from tests.support.grade import alarms, checked_run
from wcdrive.plant import ChairParams
from wcdrive.sim import runner, scenario


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


#: Each pinned case on the port; on simavr (6 s each) one at the fast depth, all three at
#: the thorough one.
@pytest.mark.parametrize(("turn", "backend"), cases([(0.4,), (0.0,), (-0.4,)], ["0.4", "0.0", "-0.4"],
                                                    fast_simavr=["0.4"]))
def test_a_stream_resumed_after_a_watchdog_stop_is_refused_without_a_fault(tmp_path: Path, turn: float,
                                                                          backend: str) -> None:
    r = checked_run(_scenario(tmp_path, 1.0, turn, 0.5), backend)
    events = [line for _, line in r.link.events]
    assert any(line.startswith("EVT:WATCHDOG") for line in events), events
    assert "EVT:NOT_NEUTRAL" in events, events
    assert alarms(r) == [], events
    # the stream resumes at 8.67 s: the plant's wheels brake to rest from 1 m/s and stay
    rest = r.board.tick_time >= 10.5
    rim = np.abs(r.truth.wheel_speed[rest]).mean(axis=1) * ChairParams().wheel_radius
    assert rim.max() < 0.03, rim.max()


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
