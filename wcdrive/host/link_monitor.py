"""The link's liveness: the time since the board's last line, ``ok`` while it is less
than ``link_timeout``, a ``LinkLost`` or ``LinkRestored`` to ``on_link`` at each change,
and the thread that watches it (and paces the hello's retries).

The reader calls ``heard`` whenever lines arrive and ``change`` when the device
vanishes; ``LinkMonitor`` does the rest on its own thread, ``wcdrive-link``.

Why the care: the host's own stall is not the board's silence. When the monitor wakes
late (the process stood still: a GC pause, an overloaded machine) or the board's bytes
wait unread in the port (the reader is behind), silence proves nothing yet, so it looks
again shortly. A simulated board may run faster or slower than the wall clock, or fall
behind it on a loaded machine and hand its output over late: with a ``board_clock``
the silence is counted on the board's clock.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from wcdrive._util.history import History
from wcdrive.host.telemetry import LinkEvent, LinkLost, LinkRestored

__all__ = ["LinkMonitor"]

_log = logging.getLogger("wcdrive.session")


class LinkMonitor:
    """The liveness of the link to the board named ``name``, until ``closed`` is set.

    ``link_timeout``: seconds without a line before the link counts as lost.
    ``board_clock``: a simulated board's clock (s; None when it cannot say).
    ``on_link`` gets each ``LinkLost``/``LinkRestored``; ``events`` notes them and
    ``errors`` a failing ``on_link``. ``wake`` runs at every change (a request in
    flight looks again), ``on_restored`` when a lost link comes back. ``pace``: the
    hello's step, called each round with the time; it returns how long the monitor may
    sleep. ``bytes_waiting``: whether the board's bytes wait unread.

    Its lock (reentrant) makes each change, and the callbacks it runs, one at a time."""

    #: The link monitor woke this much later than it meant to: the whole process stood
    #: still (a GC pause, an overloaded machine), so silence then proves nothing yet.
    STALL = 0.02

    def __init__(self, name: str, closed: threading.Event, *, link_timeout: float,
                 board_clock: Callable[[], float | None] | None,
                 on_link: Callable[[LinkEvent], None] | None,
                 events: History[str], errors: History[str],
                 wake: Callable[[], None], on_restored: Callable[[], None],
                 pace: Callable[[float], float], bytes_waiting: Callable[[], bool]) -> None:
        self.name = name
        self.link_timeout = link_timeout
        self._closed = closed
        self._board_clock = board_clock
        self._on_link = on_link
        self._events = events
        self._errors = errors
        self._wake = wake
        self._on_restored = on_restored
        self._pace = pace
        self._bytes_waiting = bytes_waiting
        self._lock = threading.RLock()
        #: Host time of the board's last line (None: none since the port was opened).
        self.last_line_at: float | None = None
        self._last_line_board_at: float | None = None   # the board's clock then (board_clock)
        self._state: bool | None = None             # None: no line yet since construction
        self._lost_at = 0.0
        self._thread = threading.Thread(target=self._run, name="wcdrive-link", daemon=True)

    def start(self) -> None:
        """Starts the monitor's thread."""
        self._thread.start()

    @property
    def ok(self) -> bool:
        """True while lines arrive from the board: the last less than
        ``link_timeout`` s ago."""
        return self._state is True and not self._closed.is_set()

    @property
    def lost(self) -> bool:
        """True once the link was lost (or closed), until lines flow again."""
        return self._state is False or self._closed.is_set()

    @property
    def since_last_line(self) -> float:
        """Seconds since the board's last line (inf before the first since the port
        was opened)."""
        last = self.last_line_at
        return float("inf") if last is None else time.monotonic() - last

    def heard(self, now: float) -> None:
        """Lines from the board arrived at host time ``now``."""
        if self._board_clock is not None:
            self._last_line_board_at = self._board_clock()
        self.last_line_at = now
        if self._state is not True:
            self.change(True, now)

    def change(self, up: bool, now: float, reason: str = "silent",
               silent_for: float | None = None) -> None:
        """The link came up or went down: note it (``events``) and tell ``on_link``,
        once per change. The first line after construction only sets ``ok``."""
        with self._lock:
            before = self._state
            if before is up or (before is None and not up) or self._closed.is_set():
                return
            self._state = up
            self._wake()                            # a request in flight gives up
            if before is None:
                return
            event: LinkEvent
            if up:
                event = LinkRestored(now, self.name, now - self._lost_at)
                _log.warning("%s: link restored after %.3f s", self.name, now - self._lost_at)
                self._events.append("LINK_RESTORED")
                self._on_restored()
            else:
                self._lost_at = now
                last = self.last_line_at
                if silent_for is None:
                    silent_for = float("inf") if last is None else now - last
                event = LinkLost(now, self.name, silent_for, reason)
                _log.warning("%s: link lost (%s)", self.name, reason)
                self._events.append("LINK_LOST")
            if self._on_link is not None:
                try:
                    self._on_link(event)
                except Exception as exc:            # a subscriber's bug must not stop the link
                    _log.exception("%s: an on_link callback failed", self.name)
                    self._errors.append(f"on_link callback failed: {exc!r}")

    def reopened(self) -> None:
        """The device was opened again: no line from the new board yet, and the old
        board's clock is gone."""
        self.last_line_at = None
        self._board_clock = self._last_line_board_at = None

    def close(self) -> None:
        """The link is closed: ``ok`` is False from now on."""
        with self._lock:
            self._state = False

    def _run(self) -> None:
        """Marks the link lost after ``link_timeout`` s without a line, and paces the
        hello's retries, until closed."""
        delay, planned = 0.0, time.monotonic()
        while not self._closed.wait(delay):
            now = time.monotonic()
            stalled = now - planned > self.STALL
            delay = self._pace(now)
            last = self.last_line_at
            if self._state is True and last is not None:
                silent = self._board_silence()
                if silent is None:                      # the host's clock
                    silent = now - last
                    left = self.link_timeout - silent
                else:                                   # the board's: it runs at its own pace
                    left = max(0.005, self.link_timeout - silent)
                if silent < self.link_timeout:
                    delay = min(delay, left)
                elif stalled or self._bytes_waiting():
                    delay = 0.01
                else:
                    self.change(False, now, silent_for=silent)
            delay = max(0.001, min(delay, 0.05))
            planned = time.monotonic() + delay

    def _board_silence(self) -> float | None:
        """Seconds of the board's clock since its last line (``board_clock``); None when
        there is no such clock, or it cannot say now (the board's thread stopped: the
        host's clock decides). A clock that went back (the board reset) counts from the
        reset."""
        clock = self._board_clock
        last = self._last_line_board_at
        if clock is None or last is None:
            return None
        now = clock()
        if now is None:
            return None
        return now - last if now >= last else now
