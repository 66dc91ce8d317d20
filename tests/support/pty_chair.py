"""A simulated board behind a pty, opened as a program opens a real chair: the host
tests' rig, and ``until``, their wait on what the chair reports."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import wcdrive
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.host.wheelchair import Wheelchair
from wcdrive.plant import ChairParams
from wcdrive.transports.pty_bridge import PtyBridge


@contextmanager
def chair_on_a_pty(speed: float = 1.0, params: ChairParams | None = None
                   ) -> Iterator[tuple[SimulatedBoard, Wheelchair]]:
    """(the board, of a chair with ``params``, and the chair ``wcdrive.connect`` opened on
    its pty, which resets the board as DTR does); both closed at the end."""
    board = SimulatedBoard(params, speed=speed)
    bridge = PtyBridge(board.start(), on_open=board.dtr).start()
    try:
        chair = wcdrive.connect(bridge.device)
        assert isinstance(chair, Wheelchair)
        with chair:
            yield board, chair
    finally:
        bridge.close()
        board.close()


def until(what: Callable[[], bool], timeout: float = 3.0) -> bool:
    """Whether ``what()`` came true within ``timeout`` s (asked every 20 ms)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if what():
            return True
        time.sleep(0.02)
    return False
