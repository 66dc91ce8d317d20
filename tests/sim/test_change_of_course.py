"""A sharp change of course is no faulty motor, watched from the plant, on both backends.

From a fast turn one way (0.95 m/s, -0.71 rad/s) to a slow turn the other (0.2 m/s,
0.37 rad/s): the wheel that was fast brakes from 7.5 toward 0.65 rad/s and stays
above its setpoint for a second, the chair's momentum carries the other wheel below
its own, and that one's duty climbs while it still slows. The motor rule took it for a
dead motor dragged along (``FAULT,MOTOR_R`` 1.7 s after the change, in a soak on a
flat floor, the host falling silent 1.4 s after the change). A wheel is counted as
dragged only while the other wheel is no more than ``FAULT_EFFORT_LEAD`` beyond its
own setpoint: one that brakes drags nothing.

A turn on a 4 degree slope: the chair's load holds both wheels back, and both duties
climb without a gain. A wheel is not counted while the other strains too (its duty
``FAULT_EFFORT_PWM`` up without a gain). (The slow change of course of a 24 h
soak, where the other wheel ran ``FAULT_EFFORT_OVERRUN`` beyond its setpoint, is run
again from its record: tests/tools/test_board_line_benchmarks.py.)
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import thorough
from tests.support.grade import alarms, checked_run
from wcdrive.sim import runner, scenario

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))


def _scenario(tmp: Path, first: tuple[float, float], then: tuple[float, float], then_s: float,
              silence_s: float, head: str = "", first_s: float = 6.0) -> scenario.Scenario:
    text = (f'name = "change_of_course"\nsettle_s = 0.5\nhost_rate_hz = 10\n{head}'
            f"[[segment]]\ncmdvel = [{first[0]}, {first[1]}]\nduration = {first_s}\n"
            f"[[segment]]\ncmdvel = [{then[0]}, {then[1]}]\nduration = {then_s}\n"
            + (f"[[segment]]\nsilence = true\nduration = {silence_s}\n" if silence_s else ""))
    path = tmp / "change_of_course.toml"
    path.write_text(text)
    return scenario.load(str(path))


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_soaks_change_of_course_is_no_fault(tmp_path: Path, backend: str) -> None:
    r = checked_run(_scenario(tmp_path, (0.949, -0.709), (0.204, 0.367), 1.4, 1.0), backend)
    events = [line for _, line in r.link.events]
    assert alarms(r) == [], events


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_turn_down_a_slope_is_no_fault(tmp_path: Path, backend: str) -> None:
    """0.5 m/s at 0.8 rad/s, 4 degrees down: as the chair comes round across the slope
    both duties climb without a gain (``FAULT,MOTOR_L`` at 5.3 s)."""
    r = checked_run(_scenario(tmp_path, (0.5, 0.8), (0.5, 0.8), 3.0, 0.0,
                              head="[world]\nslope_deg = 4.0\ndownhill_heading_deg = 0.0\n"), backend)
    assert alarms(r) == [], [line for _, line in r.link.events]


COURSES = [((0.949, -0.709), (0.204, 0.367)), ((0.949, 0.709), (0.204, -0.367)),
           ((1.0, -0.8), (0.1, 0.8)), ((1.0, 0.8), (0.3, 0.0)), ((-0.3, 0.8), (0.5, -0.8)),
           ((1.0, 0.0), (0.1, 0.5)), ((0.8, -0.8), (0.8, 0.8))]


@pytest.mark.parametrize(("first", "then"), COURSES if thorough() else COURSES[:4])
def test_sharp_changes_of_course_on_the_level_raise_no_alarm(tmp_path: Path, first: tuple[float, float],
                                                             then: tuple[float, float]) -> None:
    r = runner.run(_scenario(tmp_path, first, then, 4.0, 0.0))
    assert alarms(r) == [], (first, then, r.link.events)
