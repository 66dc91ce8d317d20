"""Neutral before motion on the host (``wcdrive.host.neutral``; docs/safety.md):
``connect`` and ``reset_estop`` send the neutral command the board needs and wait for
it to be confirmed; after a board reset mid-run the program must send one itself:
``chair.needs_neutral`` is true and motion raises ``WcdriveNeutralError`` (nothing goes
out) until ``stop()`` / ``wait_for_neutral()``. On a simulated board behind a pty, as a
program meets a real one."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from tests.support.pty_chair import chair_on_a_pty
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.errors import WcdriveNeutralError
from wcdrive.host.wheelchair import Wheelchair


@pytest.fixture
def rig() -> Iterator[tuple[SimulatedBoard, Wheelchair]]:
    with chair_on_a_pty() as pair:
        yield pair


def _drive(chair: Wheelchair, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        chair.set_velocity(0.4, 0.0)
        time.sleep(0.05)


def test_connect_leaves_a_chair_that_drives(rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    board, chair = rig
    assert not chair.needs_neutral
    assert chair.status is not None and chair.status.state == 0
    _drive(chair, 1.0)
    assert board.pose()[0] > 0.1
    assert "ERR:neutral" not in chair.errors and "neutral" not in chair.errors


def test_after_a_reset_mid_run_motion_raises_until_the_program_sends_neutral(
        rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    board, chair = rig
    _drive(chair, 0.8)
    boots = chair.boots
    board.dtr()                                       # the board resets under the drive
    end = time.monotonic() + 5.0
    while chair.boots == boots and time.monotonic() < end:
        time.sleep(0.02)
    chair.wait_for_handshake()
    assert chair.needs_neutral
    with pytest.raises(WcdriveNeutralError) as caught:
        chair.set_velocity(0.4, 0.0)
    assert caught.value.reason == "neutral" and "stop()" in str(caught.value)
    time.sleep(1.0)                                   # the chair coasts to rest, stays
    x = board.pose()[0]
    time.sleep(0.5)
    assert abs(board.pose()[0] - x) < 0.005
    chair.wait_for_neutral()
    assert not chair.needs_neutral
    _drive(chair, 1.0)
    assert board.pose()[0] > x + 0.1


def test_reset_estop_waits_for_the_neutral_the_board_then_needs(
        rig: tuple[SimulatedBoard, Wheelchair]) -> None:
    board, chair = rig
    _drive(chair, 0.5)
    chair.estop()
    chair.reset_estop()
    assert not chair.needs_neutral
    x = board.pose()[0]
    _drive(chair, 1.0)
    assert board.pose()[0] > x + 0.1
