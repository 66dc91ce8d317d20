"""The lidar's scans on the host: taken from their source (a simulated board's lidar,
``wcdrive.boards.board_lidar.BoardLidar.take``) at each telemetry tick, stamped in host
time, handed to callbacks and to ``Wheelchair.scan``.

    feed = ScanFeed(board.lidar, chair.board_clock)
    chair.on_telemetry(feed.poll)           # what ``Wheelchair`` does with ``scan_source``
    scan = feed.wait(timeout=1.0)           # the newest scan not yet returned

A scan's ``stamp`` becomes the host time of its first beam (``BoardClock.to_host`` of
the board's time then, kept in ``board_stamp``), as the telemetry's and the odometry's:
a scan and a pose can be matched by time. ``beam_time`` stays on the board's clock.
The source is read at the 20 Hz tick, so a scan reaches the host at most a tick (50 ms)
after its turn ended, besides the link's own lag.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

from wcdrive.host.boardclock import BoardClock

if TYPE_CHECKING:                     # the host side loads no simulator
    from wcdrive.plant.lidar import LaserScan, Lidar


class ScanSource(Protocol):
    """Where scans come from: a simulated board's ``BoardLidar``."""

    @property
    def lidar(self) -> Lidar:
        """The lidar (its model and mount)."""

    def take(self) -> list[LaserScan]:
        """The scans made since the last ``take``, oldest first."""


class ScanFeed:
    """Scans from ``source``, their stamps mapped by ``clock``."""

    def __init__(self, source: ScanSource, clock: BoardClock) -> None:
        self.lidar = source.lidar
        self._source, self._clock = source.take, clock
        self._cond = threading.Condition()
        self._latest: LaserScan | None = None
        self._returned: LaserScan | None = None
        self._callbacks: list[Callable[[LaserScan], None]] = []

    def poll(self, _tick: Any = None) -> None:
        """Takes the new scans (the reader thread, at each tick; ``_tick`` unused)."""
        new = [dataclasses.replace(s, stamp=self._clock.to_host(s.stamp), board_stamp=s.stamp)
               for s in self._source()]
        if not new:
            return
        with self._cond:
            self._latest = new[-1]
            callbacks = list(self._callbacks)
            self._cond.notify_all()
        for scan in new:
            for callback in callbacks:
                callback(scan)

    def on_scan(self, callback: Callable[[LaserScan], None]) -> None:
        """Calls ``callback`` with every scan, from the reader thread, oldest first."""
        with self._cond:
            self._callbacks.append(callback)

    def wait(self, timeout: float) -> LaserScan | None:
        """The newest scan that ``wait`` has not returned yet, waiting up to ``timeout``
        s for one; None if none came."""
        with self._cond:
            def fresh() -> bool:
                return self._latest is not None and self._latest is not self._returned

            if not self._cond.wait_for(fresh, timeout):
                return None
            self._returned = self._latest
            return self._returned
