"""The receive buffer of a simulated board is bounded like a serial driver's: a board
whose output nobody reads holds at most its capacity; what does not fit is dropped,
newest first, and counted (``rx_dropped``)."""

from __future__ import annotations

import time

import pytest
import serial

import wcdrive  # noqa: F401  (registers the wc*:// handlers)
from wcdrive.boards.receive_buffer import DEFAULT_CAPACITY, ReceiveBuffer
from wcdrive.boards.sim_board import SimulatedBoard, rx_capacity


def test_what_does_not_fit_is_dropped_and_counted() -> None:
    buf = ReceiveBuffer(8)
    buf.put(b"abcde")
    buf.put(b"fghij")                              # 3 fit, the newest 2 are dropped
    assert len(buf) == 8 and buf.dropped == 2
    assert buf.read(100, timeout=0) == b"abcdefgh"  # what was held, in order
    buf.put(b"klm")                                # room again once read
    assert buf.read(100, timeout=0) == b"klm" and buf.dropped == 2
    buf.put(b"012345")
    buf.clear()                                    # a flush is not a drop
    assert len(buf) == 0 and buf.dropped == 2


def test_the_default_is_a_linux_tty_and_a_capacity_is_positive() -> None:
    assert ReceiveBuffer().capacity == DEFAULT_CAPACITY == 4096
    with pytest.raises(ValueError, match="capacity"):
        ReceiveBuffer(0)


def test_the_simulated_boards_buffer_holds_a_tty_and_one_step() -> None:
    """4096 bytes plus what one step of the board's thread can hand over: a second of
    the UART (10,696 bytes) up to speed 125, then 8 ms of wall clock's worth."""
    assert rx_capacity(1.0) == rx_capacity(20.0) == 4096 + 10696
    assert rx_capacity(1000.0) == 4096 + 85562


def test_a_board_nobody_reads_stays_bounded() -> None:
    """``wcsim://?speed=100`` left unread for 1 s sends about 70 kB: the buffer holds its
    capacity, the rest is counted as dropped, and what is held is the oldest output
    (the BOOT line first), as a driver that drops bytes arriving at a full buffer."""
    port = serial.serial_for_url("wcsim://?speed=100", timeout=0.1)
    try:
        capacity = rx_capacity(100.0)
        time.sleep(1.0)
        assert port.in_waiting <= capacity
        assert port.in_waiting == capacity and port.rx_dropped > 10 * DEFAULT_CAPACITY
        held = port.read(capacity)
        assert held.startswith(b"BOOT:final_control,POWER_ON\r\n")
        dropped = port.rx_dropped
        assert port.read(4096)                     # the board goes on: new output is taken again
        assert port.rx_dropped >= dropped
    finally:
        port.close()


def test_a_board_that_is_read_drops_nothing() -> None:
    board = SimulatedBoard(speed=100).start()
    try:
        received = 0
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            received += len(board.read(100_000, timeout=0.05))
        assert received > 10 * DEFAULT_CAPACITY and board.rx_dropped == 0
    finally:
        board.close()
