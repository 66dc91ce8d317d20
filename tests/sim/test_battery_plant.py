"""The low battery with the plant (docs/safety.md, "The battery"): the plant's battery
sags under the current the motors draw, and the board reads the sag on A0. The bundled
``battery_low_flat`` and ``ramp_battery_cutoff_1in20`` hold their ``[expect]`` on both
backends (tests/sim/test_scenario_contracts.py); here their twins on a charged battery,
which must draw no battery event, on the port."""

from __future__ import annotations

import dataclasses

import pytest

from tests.support.grade import alarms
from wcdrive.sim import runner, scenario


def _charged(name: str) -> runner.SimResult:
    sc = scenario.load(name)
    chair = {**sc.chair, "battery_charge": 1.0, "battery_resistance": 0.05}
    chair.pop("battery_empty_voltage", None)
    return runner.run(dataclasses.replace(sc, chair=chair, expect=None), backend="port")


def test_a_charged_battery_rides_the_same_drive_without_an_event() -> None:
    """``battery_low_flat`` on a full battery (25.6 V at rest, 0.05 ohm): the sag of the
    start leaves it at 24.3 V or more, far from the 23 V rollback; no event, and the chair
    drives 24.3 m in the 10 s, against the worn battery's 22.1."""
    r = _charged("battery_low_flat")
    m = r.metrics()
    assert [line for _, line in r.link.events if "BATTERY" in line or "EVT:FAULT" in line] == []
    assert m["battery_min_v"] >= 24.3 and m["distance_m"] == pytest.approx(24.3, abs=0.5)


def test_a_charged_battery_climbs_the_grade_the_worn_one_cannot_start() -> None:
    """``ramp_battery_cutoff_1in20`` on a full battery: 100 kg up 1:20 at 1 m/s for 6 s
    climbs more than 4 m, with no alarm."""
    r = _charged("ramp_battery_cutoff_1in20")
    assert alarms(r) == [] and r.metrics()["truth_x"] > 4.0
