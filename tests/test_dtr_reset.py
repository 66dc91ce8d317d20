"""The DTR model (issue 17): opening a simulated board's pty resets it, as opening a
real Mega's port does, and the host copes with that and with a reset mid-run: it
greets the board again, drives on, and its odometry carries on from where it was
instead of jumping back to the origin when the board's counts restart at 0."""

from __future__ import annotations

import time

import pytest
import serial

import wcdrive
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.boards.simavr.mega_board import MegaBoard
from wcdrive.transports.pty_bridge import PtyBridge


def test_opening_the_pty_resets_the_board_every_time() -> None:
    board = SimulatedBoard()
    bridge = PtyBridge(board.start(), on_open=board.reset).start()
    try:
        boots = []
        for _ in range(3):
            with serial.Serial(bridge.device, 115200, timeout=0.05) as link:
                data = b""
                end = time.monotonic() + 0.6
                while time.monotonic() < end:
                    data += link.read(256)
            boots.append(data.count(b"BOOT:"))
        assert boots == [1, 1, 1] and bridge.opens == 3
    finally:
        bridge.close()


def _drive(chair: wcdrive.Wheelchair, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            chair.set_velocity(0.4, 0.0)
        except wcdrive.WcdriveError:
            pass                              # between the reset and the new hello
        time.sleep(0.05)


@pytest.mark.simavr
def test_a_reset_mid_run_is_greeted_again_and_odometry_carries_on(elf) -> None:
    board = MegaBoard(elf, realtime=True)
    bridge = PtyBridge(board, on_open=board.reset).start()
    board.start()
    try:
        with wcdrive.connect(bridge.device) as chair:
            assert chair.reset_cause == "EXTERNAL"            # the open reset it
            _drive(chair, 2.0)
            before = chair.odometry.pose.x
            assert before > 0.1
            board.reset()                                     # DTR pulse, the chair rolling
            _drive(chair, 1.5)
            assert "BOARD_RESET" in chair.events and chair.protocol_version == 3
            after = chair.odometry.pose.x
            truth = board.pose()[0]
            # Counts from 0 again on the board; the pose went on forward (without the
            # re-base it would have jumped back by about `before`).
            assert after > before + 0.1, (before, after)
            assert abs(after - truth) < 0.25 * truth, (after, truth)
    finally:
        bridge.close()
