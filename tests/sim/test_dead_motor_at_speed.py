"""A motor that dies at speed is caught, watched from the plant, on both backends.

At 1 m/s and more the chair's momentum and the other wheel drag the dead motor's wheel
along at 87 to 93 % of its setpoint: the motor rule counts only below
``FAULT_EFFORT_SHORTFALL_MOTOR`` of it. At 80 % (the grade rule's
``FAULT_EFFORT_SHORTFALL``) neither drive below latched anything in 12.5 s: the chair
drove 17 m and turned 195 degrees on one motor (``benchmarks/motor_rule.py``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.support.depth import cases
from tests.support.grade import checked_run
from wcdrive.sim import scenario

BACKENDS = ("port", pytest.param("simavr", marks=pytest.mark.simavr))
DEAD_AT = 3.0


#: Both on the port; on simavr the right motor's at the fast depth (the slope's case below
#: takes the left's there), both at the thorough one.
@pytest.mark.parametrize(("speed", "side", "backend"), cases(
    [(1.0, "left"), (1.5, "right")], ["1.0-left", "1.5-right"], fast_simavr=["1.5-right"]))
def test_a_motor_dead_at_speed_latches_its_fault_and_the_chair_stops(tmp_path: Path, speed: float, side: str,
                                                                      backend: str) -> None:
    path = tmp_path / "dead_at_speed.toml"
    path.write_text(f'name = "dead_at_speed"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
                    f"[[segment]]\ncmdvel = [{speed}, 0.0]\nduration = 9.0\n"
                    f'[[fault]]\nat = {DEAD_AT}\nkind = "motor_dead"\nside = "{side}"\n')
    r = checked_run(scenario.load(str(path)), backend)
    assert r.fault_at is not None
    faults = [(t, line) for t, line in r.link.events if line.startswith("EVT:FAULT")]
    assert faults and faults[0][1] == f"EVT:FAULT,MOTOR_{side[0].upper()}", r.link.events
    assert faults[0][0] - r.fault_at <= 1.5
    # the plant at rest at the end, the motors unpowered or holding
    assert np.all(np.abs(r.truth.wheel_speed[-5:]) < 0.05), r.truth.wheel_speed[-5:]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_motor_dead_going_down_a_slope_is_caught_though_its_partner_strains(tmp_path: Path,
                                                                              backend: str) -> None:
    """1.5 m/s straight down 4 degrees, the left motor dead: its partner's duty climbs
    while it drags it, at 96 to 99 % of its setpoint. That is no effort without
    progress (``effortRising`` counts only below ``FAULT_EFFORT_SHORTFALL_MOTOR``), so it
    does not excuse the dead wheel: ``MOTOR_L`` within 6 s (5.25 s), the chair stopped."""
    path = tmp_path / "dead_downhill.toml"
    path.write_text(f'name = "dead_downhill"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
                    f"[world]\nslope_deg = 4.0\ndownhill_heading_deg = 0.0\n"
                    f"[[segment]]\ncmdvel = [1.5, 0.0]\nduration = 10.0\n"
                    f'[[fault]]\nat = {DEAD_AT}\nkind = "motor_dead"\nside = "left"\n')
    r = checked_run(scenario.load(str(path)), backend)
    assert r.fault_at is not None
    faults = [(t, line) for t, line in r.link.events if line.startswith("EVT:FAULT")]
    assert faults and faults[0][1] == "EVT:FAULT,MOTOR_L", r.link.events
    assert faults[0][0] - r.fault_at <= 6.0
