"""The parking brake on the host (docs/safety.md, "The parking brake"): a simulated chair
with a brake behind a pty. ``set_param("brake_fitted", 1)`` hands the brake to the
firmware; ``status.brake_applied`` (TLM ``state`` bit 4) follows it, applied at rest and
let go to drive; a coil that fails while parked (``SimulatedBoard.set_brake_coil``) is
``chair.faults == ("BRAKE_OPEN",)``, and motion raises ``WcdriveFaultError`` while the
chair stays put. The lever pulled (push mode) is ``status.push_mode`` and a
``WcdriveInhibitError`` that names it."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

import wcdrive
from tests.support.pty_chair import chair_on_a_pty, until
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.host.wheelchair import Wheelchair
from wcdrive.plant import ChairParams


@pytest.fixture
def rig() -> Iterator[tuple[SimulatedBoard, Wheelchair]]:
    with chair_on_a_pty(speed=2.0, params=ChairParams(parking_brake=True)) as pair:
        yield pair


def _applied(chair: Wheelchair) -> bool:
    status = chair.status
    return status is not None and status.brake_applied


def test_the_brake_is_applied_at_rest_released_to_drive_and_its_open_coil_stops_motion(
        rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    board, chair = rig
    assert chair.set_param("brake_fitted", 1) == 1
    assert until(lambda: _applied(chair))
    assert board.plant.brake_engaged
    released = False
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        chair.set_velocity(0.4, 0.0)
        released = released or not _applied(chair)
        time.sleep(0.05)
    assert released and board.pose()[0] > 0.05
    chair.stop()
    assert until(lambda: _applied(chair), 5.0)
    parked = board.pose()[0]
    board.set_brake_coil("open")
    assert until(lambda: chair.faults == ("BRAKE_OPEN",))
    assert "FAULT,BRAKE_OPEN" in chair.events
    with pytest.raises(wcdrive.WcdriveFaultError):
        chair.set_velocity(0.4, 0.0)
    time.sleep(0.5)
    assert abs(board.pose()[0] - parked) < 0.005


def test_push_mode_refuses_motion_naming_it_and_asks_for_neutral_after(
        rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    """The lever pulled (``set_inhibit("push")``): ``status.push_mode``, and motion raises
    ``WcdriveInhibitError`` naming push mode; back, ``PUSH,0`` and the chair needs a neutral
    command (``wait_for_neutral``) before it drives again."""
    board, chair = rig
    chair.wait_for_neutral()
    board.set_inhibit("push")
    assert until(lambda: chair.status is not None and chair.status.push_mode)
    with pytest.raises(wcdrive.WcdriveInhibitError, match="push mode"):
        chair.set_velocity(0.4, 0.0)
    board.set_inhibit("push", False)
    assert until(lambda: "PUSH,0" in chair.events)
    assert until(lambda: chair.status is not None and not chair.status.push_mode)
    chair.wait_for_neutral()
    start = board.pose()[0]
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        chair.set_velocity(0.4, 0.0)
        time.sleep(0.05)
    assert board.pose()[0] > start + 0.05
