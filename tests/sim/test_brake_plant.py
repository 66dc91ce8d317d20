"""The parking brake the firmware owns (``brake_fitted`` 1), watched on the chair: parked
on the brake the motors are unpowered and the chair stays put, beyond the grade the hold
carries too; an uphill start from the brake rolls back within a bound; a board told it
has a brake that the chair lacks sees an open coil. (The coil faults while driving and
parked are bundled scenarios with ``[expect]`` contracts, ``fault_brake_short`` and
``fault_brake_open``: tests/sim/test_scenario_contracts.py, both backends.)

The port runs at every depth; simavr, held bit for bit to the port, at the thorough one
(the firmware's brake is held to the port at the fast depth by tests/firmware/test_brake.py).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.conftest import thorough
from tests.support.grade import alarms, bundled, checked_run
from wcdrive.sim import scenario
from wcdrive.sim.scenario import Scenario, Segment

BACKENDS = ["port", pytest.param("simavr", marks=pytest.mark.simavr)] if thorough() else ["port"]

#: m: the uphill start's roll back from the engaged brake, and without a brake, on
#: 1:12 from the hold (measured 20.3 mm and 9.6 mm on both backends).
ROLLBACK_BRAKE_M = 0.025
ROLLBACK_PLAIN_M = 0.012


def _travel(r, t0: float) -> np.ndarray:
    """m along the chair's heading from where it stood at ``t0`` s, at each tick after."""
    t = r.board.tick_time
    k0 = int(np.searchsorted(t, t0))
    heading = r.truth.pose[k0, 2]
    d = r.truth.pose[k0:, :2] - r.truth.pose[k0, :2]
    return d[:, 0] * np.cos(heading) + d[:, 1] * np.sin(heading)


@pytest.mark.parametrize("backend", BACKENDS)
def test_parked_on_the_brake_the_motors_are_unpowered_and_the_chair_stays(backend: str) -> None:
    """Up and down 1:12 with a stop held 5 s between (``ramp_up_down_1in12_brake``):
    within 2 s of each stop command (the ramp down from the climb's full duty, or
    braking down the grade) both duties reach 0 and stay 0 to the stop's end (the hold
    does not drive against the brake, as it did before the firmware knew of it: 17 to
    19 of 255 on 1:20), and from then the chair moves less than a millimetre."""
    r = bundled("ramp_up_down_1in12_brake", backend)
    assert not alarms(r)
    t = r.board.tick_time
    duty = np.abs(r.board.pwm).max(axis=1)
    for start, end in ((4.17, 9.17), (13.17, 19.17)):
        window = np.flatnonzero((t >= start) & (t < end))
        driven = window[duty[window] > 0]
        rest = driven[-1] + 1
        assert t[rest] < start + 2.0, (start, t[rest])
        assert end - t[rest] > 3.0
        pose = r.truth.pose[rest:window[-1] + 1, :2]
        assert np.hypot(*(pose - pose[0]).T).max() < 1e-3, (start, end)


@pytest.mark.parametrize("backend", BACKENDS)
def test_ten_degrees_parked_holds_on_the_brake_and_not_without_it(backend: str) -> None:
    """Parked facing down 10 degrees for 15 s (``ramp_park_10deg_brake``, twice the rated
    grade): on the brake the chair stays within 5 mm, no alarm, the motors unpowered
    from the brake's engage time on; the same chair without a brake (the hold alone)
    does not stay (docs/safety.md, "Not safe yet")."""
    braked = bundled("ramp_park_10deg_brake", backend)
    assert not alarms(braked)
    assert np.hypot(*(braked.truth.pose[-1, :2] - braked.truth.pose[0, :2])) < 0.005
    t = braked.board.tick_time
    assert np.all(braked.board.pwm[t > 0.5] == 0)
    if backend == "port":
        sc = scenario.load("ramp_park_10deg_brake")
        plain = dataclasses.replace(sc, chair={}, board_params={})
        r = checked_run(plain, backend)
        assert np.hypot(*(r.truth.pose[-1, :2] - r.truth.pose[0, :2])) > 0.1


def _uphill_start(brake: bool) -> Scenario:
    """Facing up 1:12, stops for 1 s (the brake engaged, or the hold carrying the
    chair), then 0.5 m/s for 4 s."""
    sc = scenario.load("ramp_park_1in12_brake")
    segments = (Segment("stop", (), 1.0), Segment("cmdvel", (0.5, 0.0), 4.0))
    return dataclasses.replace(
        sc, segments=segments, terrain=dataclasses.replace(sc.terrain, slope_deg=-sc.terrain.slope_deg),
        chair=sc.chair if brake else {}, board_params=sc.board_params if brake else {})


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_uphill_start_from_the_brake_rolls_back_within_its_bound(backend: str) -> None:
    """The start up 1:12 after 1 s parked: from the engaged brake the chair rolls back
    at most ROLLBACK_BRAKE_M before it climbs (the hold's preload is its duty at the
    moment, 0 after a park on the brake: the board measures no grade before the wheels
    move); the chair without a brake, which the hold already carried, at most
    ROLLBACK_PLAIN_M. Both then climb (at the driver's 13 A current limit, slowly: 0.1 m
    in the 4 s)."""
    for brake, bound in ((True, ROLLBACK_BRAKE_M), (False, ROLLBACK_PLAIN_M)):
        sc = _uphill_start(brake)
        r = checked_run(sc, backend)
        assert not alarms(r), brake
        along = _travel(r, sc.segments_start + 1.0)
        assert -along.min() <= bound, (brake, along.min())
        assert along[-1] > 0.05, (brake, along[-1])


def test_a_board_told_of_a_brake_the_chair_lacks_sees_an_open_coil() -> None:
    """brake_fitted 1 on a chair without a brake: the driver has nothing on its output
    (an open load), so the first parked ticks latch ``EVT:FAULT,BRAKE_OPEN``; the hold,
    powered again, catches the chair as it catches one without a brake at switch-on
    (12 mm on 1:12), and it moves no more."""
    sc = dataclasses.replace(_uphill_start(True), chair={})
    r = checked_run(sc, "port")
    assert [line for _, line in r.link.events if line.startswith("EVT:FAULT")] == ["EVT:FAULT,BRAKE_OPEN"]
    fault_at = next(t for t, line in r.link.events if line.startswith("EVT:FAULT"))
    assert fault_at < 0.3
    along = _travel(r, 0.0)
    assert np.abs(along).max() < 0.015
    assert np.ptp(along[-40:]) < 1e-3


@pytest.mark.parametrize("backend", BACKENDS)
def test_pushed_by_hand_down_a_grade_the_motors_freewheel_then_brake(backend: str) -> None:
    """Parked facing down 1:12 with the brake (``ramp_push_mode_1in12_brake``), its lever
    pulled at 1 s: the chair rolls off, freewheeling (it passes 0.4 m/s within 1.2 s),
    is held by the shorted motors near PUSH_SPEED (0.61 m/s at the rim; never over
    0.8 m/s), with no alarm; the lever back at 6 s, the brake stops it within 0.3 s and it
    stands."""
    r = bundled("ramp_push_mode_1in12_brake", backend)
    assert not alarms(r)
    t, pose = r.board.tick_time, r.truth.pose
    speed = np.r_[0.0, np.hypot(*np.diff(pose[:, :2], axis=0).T) / np.diff(t)]
    assert speed[(t > 2.2) & (t < 6.0)].max() < 0.8
    held = speed[(t > 2.2) & (t < 6.0)]                  # held near PUSH_SPEED: 0.61 m/s
    assert np.median(held) == pytest.approx(0.61, abs=0.03) and held.min() > 0.55 and held.max() < 0.7
    assert speed[(t > 1.0) & (t < 2.2)].max() > 0.4
    assert speed[(t > 0.2) & (t < 1.0)].max() < 1e-3
    stood = t > 6.3
    assert np.hypot(*(pose[stood, :2] - pose[stood][0, :2]).T).max() < 1e-3
