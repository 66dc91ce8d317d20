"""The inhibit inputs on the host (docs/safety.md, "Inhibit inputs"): a simulated board
behind a pty, its charger input pulled low (``SimulatedBoard.set_inhibit``) as a real
chair's charger plug does. ``chair.inhibited`` follows the board's TLM state; motion
raises ``WcdriveInhibitError`` (nothing goes out) while it is engaged, and the board
stops the chair; the charger latches until released and ``reset_estop()``, after which
the chair drives again. The seat input caps the speed (``status.speed_capped``)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

import wcdrive
from tests.support.pty_chair import chair_on_a_pty, until
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.host.wheelchair import Wheelchair


@pytest.fixture
def rig() -> Iterator[tuple[SimulatedBoard, Wheelchair]]:
    with chair_on_a_pty(speed=2.0) as pair:
        yield pair


def _speed(board: SimulatedBoard) -> float:
    """The chair's speed (m/s) from its wheels'."""
    return (abs(board.plant.left.speed) + abs(board.plant.right.speed)) / 2 * board.params.wheel_radius


def _drive(chair: Wheelchair, seconds: float, speed: float = 0.5) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        chair.set_velocity(speed, 0.0)
        time.sleep(0.05)


def test_the_charger_stops_the_chair_and_motion_raises_until_released_and_reset(
        rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    board, chair = rig
    _drive(chair, 0.8)
    assert board.pose()[0] > 0.05 and not chair.inhibited
    board.set_inhibit("charger")
    with pytest.raises(wcdrive.WcdriveInhibitError):
        _drive(chair, 1.0)                            # raises once the TLM line says so
    assert chair.inhibited and "INHIBIT,1,1" in chair.events
    assert until(lambda: _speed(board) < 0.01, 5.0)
    parked = board.pose()[0]
    board.set_inhibit("charger", False)               # unplugged: still latched
    time.sleep(0.5)
    assert chair.inhibited
    with pytest.raises(wcdrive.WcdriveInhibitError):
        chair.set_velocity(0.5, 0.0)
    assert abs(board.pose()[0] - parked) < 0.01
    chair.reset_estop()                               # ends the latch, waits for neutral
    assert until(lambda: not chair.inhibited)
    _drive(chair, 0.8)
    assert board.pose()[0] > parked + 0.05


def test_the_seat_caps_the_speed_without_refusing(rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    board, chair = rig
    board.set_inhibit("seat")
    assert until(lambda: chair.status is not None and chair.status.speed_capped)
    assert not chair.inhibited
    _drive(chair, 2.5, speed=2.0)
    cap = 0.3 * 17.59 * 0.1524                        # INHIBIT_2_SPEED of max_wheel, in m/s
    assert 0.6 * cap < _speed(board) < 1.05 * cap
