"""Backend faults found by the contract suite that its shared tests reach only slowly."""

from __future__ import annotations

import threading
import time

from tests.transports.contract.conftest import assert_no_new_threads
from wcdrive.transports.pty_bridge import PtyBridge


class FloodingBoard:
    """A board that always has 4 kB to send: fills a pty nobody reads in milliseconds."""

    def __init__(self) -> None:
        self.closed = False

    def write(self, data: bytes) -> int:
        return len(data)

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        return b"ENC:0,0,VEL:0.00,0.00,MODE:CMDVEL\r\n" * (size // 35)

    def close(self) -> None:
        self.closed = True


def test_pty_bridge_closes_promptly_when_nobody_reads_the_device() -> None:
    """The bridge used to write the board's bytes to the pty master with a blocking
    write: once nobody read the device and the pty's buffer was full, its thread hung
    for good, and ``close`` waited 2 s for it and left it running."""
    before = set(threading.enumerate())
    board = FloodingBoard()
    bridge = PtyBridge(board).start()
    time.sleep(0.5)                                  # far more than a pty buffers
    t0 = time.monotonic()
    bridge.close()
    assert time.monotonic() - t0 < 1.0
    assert board.closed
    assert_no_new_threads(before, grace=1.0)
