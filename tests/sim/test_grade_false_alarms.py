"""No false alarm within the rated grade: a hypothesis sweep of grades, headings, speeds,
turns and loads on the port, each a drive, a turn and a stop held for a while; the board
sends no ``EVT:FAULT``, ``EVT:ROLLAWAY``, ``EVT:OVERSPEED`` or ``EVT:STALLED_ON_GRADE``.

The grade is at most 90 % of the rated grade of the drawn occupant (``rated_grade``), so
the motors can always hold and climb it; the speeds stay at or under 1.5 m/s (from top
speed, a stop down 1:12 trips OVERSPEED: docs/safety.md, "Not safe yet").
"""

from __future__ import annotations

from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import thorough
from wcdrive.plant import ChairParams
from wcdrive.sim import runner, scenario

ALARMS = ("EVT:FAULT", "EVT:ROLLAWAY", "EVT:OVERSPEED", "EVT:STALLED_ON_GRADE")


@st.composite
def drives(draw: st.DrawFn) -> str:
    occupant = draw(st.sampled_from([40.0, 80.0, 150.0]))
    rated = ChairParams(occupant_mass=occupant).rated_grade()
    slope = draw(st.floats(0.0, 0.9 * rated))
    heading = draw(st.sampled_from([0.0, 90.0, 180.0, 270.0, 45.0, 225.0]))
    speed = draw(st.sampled_from([0.3, 0.5, 1.0, 1.5]))
    turn = draw(st.sampled_from([0.0, 0.3, -0.5, 1.0]))
    return (f'name = "sweep"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
            f"[world]\nslope_deg = {slope}\ndownhill_heading_deg = {heading}\n"
            f"[chair]\noccupant_mass = {occupant}\n"
            f"[[segment]]\ncmdvel = [{speed}, 0.0]\nduration = 3.0\n"
            f"[[segment]]\ncmdvel = [{speed / 2}, {turn}]\nduration = 2.0\n"
            f"[[segment]]\ncmdvel = [0.0, 0.0]\nduration = 4.0\n")


@settings(max_examples=300 if thorough() else 30, deadline=None)
@given(text=drives())
def test_no_alarm_on_a_drive_within_the_rated_grade(tmp_path_factory, text: str) -> None:
    path = Path(tmp_path_factory.mktemp("sweep")) / "sweep.toml"
    path.write_text(text)
    r = runner.run(scenario.load(str(path)))
    alarms = [(t, line) for t, line in r.link.events if line.startswith(ALARMS)]
    assert alarms == [], text
