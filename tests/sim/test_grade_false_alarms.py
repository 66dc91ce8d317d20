"""No false alarm within the rated grade: a hypothesis sweep of grades, headings, speeds,
turns, loads and batteries on the port, each a drive, a turn and a stop held for a
while; the board sends no ``EVT:FAULT``, ``EVT:ROLLAWAY``, ``EVT:OVERSPEED`` or
``EVT:STALLED_ON_GRADE``.

The grade is at most 90 % of the rated grade of the drawn occupant (``rated_grade``), so
the motors can always hold and climb it; the speeds go up to the full-speed command
(2.68 m/s, reached downhill within the 5 s drive), the battery from its 24 V rating down
to 21 V (low), and the turns up to 1 rad/s (one found a false MOTOR fault, pinned
below).
"""

from __future__ import annotations

from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from tests.conftest import thorough
from tests.support.grade import alarms
from wcdrive.plant import ChairParams
from wcdrive.sim import runner, scenario


@st.composite
def drives(draw: st.DrawFn) -> str:
    occupant = draw(st.sampled_from([40.0, 80.0, 150.0]))
    rated = ChairParams(occupant_mass=occupant).rated_grade()
    slope = draw(st.floats(0.0, 0.9 * rated))
    heading = draw(st.sampled_from([0.0, 90.0, 180.0, 270.0, 45.0, 225.0]))
    speed = draw(st.sampled_from([0.3, 0.5, 1.0, 1.5, 2.0, 2.68]))
    turn = draw(st.sampled_from([0.0, 0.2, -0.2, 0.5, -0.5, 1.0, -1.0]))
    battery = draw(st.sampled_from([24.0, 22.5, 21.0]))
    return (f'name = "sweep"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
            f"[world]\nslope_deg = {slope}\ndownhill_heading_deg = {heading}\n"
            f"[chair]\noccupant_mass = {occupant}\nbattery_voltage = {battery}\n"
            f"[[segment]]\ncmdvel = [{speed}, 0.0]\nduration = 5.0\n"
            f"[[segment]]\ncmdvel = [{speed / 2}, {turn}]\nduration = 2.0\n"
            f"[[segment]]\ncmdvel = [0.0, 0.0]\nduration = 4.0\n")


@settings(max_examples=300 if thorough() else 30, deadline=None)
@given(text=drives())
def test_no_alarm_on_a_drive_within_the_rated_grade(tmp_path_factory, text: str) -> None:
    path = Path(tmp_path_factory.mktemp("sweep")) / "sweep.toml"
    path.write_text(text)
    r = runner.run(scenario.load(str(path)))
    assert alarms(r) == [], text


TURN_CLIMBING = """name = "turn_climbing"
settle_s = 0.5
host_rate_hz = 10
[world]
slope_deg = 4.0
downhill_heading_deg = 180.0
[[segment]]
cmdvel = [0.3, 0.0]
duration = 3.0
[[segment]]
cmdvel = [0.15, 1.0]
duration = 2.0
[[segment]]
cmdvel = [0.0, 0.0]
duration = 4.0
"""


def test_a_turn_while_climbing_latches_no_fault(tmp_path: Path) -> None:
    """Found by the sweep with sharper turns: up 4 degrees at 0.3 m/s, then 0.15 m/s at
    1 rad/s. The outer wheel, at its current limit, gains no speed however the duty rises,
    and MOTOR_R latched 1.05 s into the turn; it leads the inner wheel by 1.4 rad/s, so
    its motor works (``noEffect``'s lead)."""
    path = tmp_path / "turn.toml"
    path.write_text(TURN_CLIMBING)
    r = runner.run(scenario.load(str(path)))
    assert not alarms(r)


TURN_ACROSS = TURN_CLIMBING.replace("duration = 3.0", "duration = 5.0", 1).replace(
    "slope_deg = 4.0\ndownhill_heading_deg = 180.0",
    "slope_deg = 0.5998898145857104\ndownhill_heading_deg = 0.0\n"
    "[chair]\noccupant_mass = 150.0\nbattery_voltage = 21.0")


def test_a_wheel_turning_round_on_a_grade_is_no_stall(tmp_path: Path) -> None:
    """Found by the sweep with sharper turns: 0.15 m/s at 1 rad/s from 0.3 m/s, across
    0.6 degrees with a 150 kg occupant on a low battery. The inner wheel turns round, and
    stands two ticks without a count while its duty builds; ENC_STALL_L latched
    (``checkWheel``: a wheel turning round has FAULT_STALL_TICKS_TURNING ticks)."""
    path = tmp_path / "across.toml"
    path.write_text(TURN_ACROSS)
    r = runner.run(scenario.load(str(path)))
    assert not alarms(r)
