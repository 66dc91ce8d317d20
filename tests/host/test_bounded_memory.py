"""Long sessions hold flat memory: every history of a long-lived object is a ring
buffer with a settable bound (``wcdrive._util.history.History``, the telemetry's deque, a
live board's gyro samples), shown by ``tracemalloc`` over a 10-minute ``sim://``
session (run at 100 times the wall clock), and the ``wcdrive`` loggers report what
happens on the link."""

from __future__ import annotations

import collections
import gc
import logging
import time
import tracemalloc

import pytest

import wcdrive
from tests.support.board_of import board_of
from wcdrive._util.history import History
from wcdrive.errors import WcdriveNeutralError

SPEED = 100.0
#: The bound the session runs with: 1,000 ticks is 50 s of feedback, so a history that
#: were not bounded would hold 12,000 ticks at the end.
LIMIT = 1000


def test_history_is_a_bounded_list() -> None:
    h: History[int] = History(range(5), maxlen=3)
    assert h == [2, 3, 4] and h.dropped == 2
    h.append(5)
    h.extend([6, 7])
    assert h == [5, 6, 7] and isinstance(h, list)
    h.maxlen = 2
    assert h == [6, 7] and h.dropped == 6
    with pytest.raises(ValueError):
        h.maxlen = 0


def _settled(chair: wcdrive.Wheelchair) -> int:
    """Traced bytes once the reader has taken everything the board sent."""
    port = chair._session.port
    deadline = time.monotonic() + 5.0
    while port.in_waiting and time.monotonic() < deadline:
        time.sleep(0.01)
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


class _Counting(logging.Handler):
    """Counts the wcdrive log records by their text after the URL (constant memory,
    unlike pytest's caplog, which keeps every record)."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.counts: collections.Counter[str] = collections.Counter()

    def emit(self, record: logging.LogRecord) -> None:
        self.counts[record.getMessage().partition(": ")[2][:40]] += 1


@pytest.mark.thorough       # a soak: 12 s, CI's depth
def test_ten_minute_sim_session_holds_flat_memory() -> None:
    logger = logging.getLogger("wcdrive")
    handler, level = _Counting(), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False          # pytest's own log capture keeps every record
    tracemalloc.start()
    try:
        with wcdrive.connect(f"sim://?speed={SPEED:g}", link_timeout=5.0) as chair:
            chair.history_limit = LIMIT
            for _ in range(1100):         # fills the port's cache of unframed lines (1,024)
                chair.set_velocity(0.0, 0.0)
            board = board_of(chair._session.port)
            marks: dict[int, int] = {}
            k = 0
            while board.time < 600.0:
                k += 1
                try:                      # forward and back; pauses let the watchdog fire
                    if k % 60 < 50:
                        chair.set_velocity(0.3 if (k // 60) % 2 else -0.3, 0.2)
                except WcdriveNeutralError:
                    chair.stop()          # after a watchdog stop: drives on after a neutral
                except wcdrive.WcdriveConnectionError:
                    pass                  # a loaded machine stalls the board's thread now and then
                time.sleep(0.1 / SPEED)
                for mark in (240, 420):
                    if mark not in marks and board.time >= mark:
                        marks[mark] = _settled(chair)
            marks[600] = _settled(chair)
            ticks = len(chair.telemetry_arrays()["time"])
            events = len(chair.events)
    finally:
        tracemalloc.stop()
        logger.removeHandler(handler)
        logger.setLevel(level)
        logger.propagate = True
    # From 240 s on every bounded store is full: the histories (1,000 ticks: 50 s), the
    # port's parse caches (1,024 frames, filled at the start) and the session's memory
    # of recent sequence numbers.
    growth = marks[600] - marks[240]
    print(f"traced memory at 240/420/600 s: {marks[240] / 1e6:.3f} / {marks[420] / 1e6:.3f} / "
          f"{marks[600] / 1e6:.3f} MB; growth 240->600 s: {growth / 1e3:.0f} kB")
    assert ticks == LIMIT
    assert 0 < events <= LIMIT
    # 360 simulated seconds: 7,200 feedback lines, 7,200 TLM lines and 144,000 gyro
    # samples went by (kept, they would take several MB). The growth levels off (about
    # 48 kB from 240 to 420 s, 10 kB from 420 to 600 s): 60 kB in all on a quiet machine,
    # 100 kB seen beside a loaded test run.
    assert growth < 200_000, f"memory grew by {growth / 1e3:.0f} kB over 360 simulated s"
    assert any(m.startswith("connected, protocol v4") for m in handler.counts), handler.counts
    # a watchdog stop is logged with what it asks of the program (a neutral command)
    watchdog = "WATCHDOG: the board may need a neutral command before it drives again"[:40]
    assert handler.counts[watchdog] >= 10, handler.counts


@pytest.mark.simavr
def test_a_live_simavr_board_keeps_no_log_that_grows(elf) -> None:
    """``wcavr://``'s board (a ``MegaBoard``) runs for hours: after 2 simulated seconds of
    commands and feedback it holds none of the hooked entries nor the bytes it was sent
    (the lock-step harness's records), and its gyro keeps its newest samples only. Kept,
    they grew 94 MB in the soak's half hour (benchmarks/soak.py --backend simavr)."""
    from wcdrive.boards.sim_board import GYRO_HISTORY
    from wcdrive.boards.simavr.mega_board import MegaBoard
    from wcdrive.protocol.codec import encode_cmdvel

    board = MegaBoard(elf).start()
    try:
        deadline = time.monotonic() + 30.0
        while board.time < 2.0 and time.monotonic() < deadline:
            board.write(encode_cmdvel(0.5, 0.1))
            board.read(4096)
            time.sleep(0.02)
        assert board.time >= 2.0
        with board._lock:
            assert board.mega.hit_log == [] and board.mega.rx_wire == []
            gyro = board._pins.gyro                   # type: ignore[union-attr]
            assert isinstance(gyro.times, History) and gyro.times.maxlen == GYRO_HISTORY
            assert isinstance(gyro.rates, History) and len(gyro.rates) > 0
    finally:
        board.close()
