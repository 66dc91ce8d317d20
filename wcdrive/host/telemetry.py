"""Telemetry: what the board reports each tick, kept and fanned out to subscribers, and
the odometry computed from it.

``TelemetryHub.deliver`` is called by the session's reader thread for every feedback
line (with the ``TLM:`` line of the same tick after hello); iterators, callbacks,
the history arrays and the odometry all read from here. ``TelemetryHub.deliver_link``
gets the link's state changes (``LinkLost``, ``LinkRestored``) for the subscribers
that asked for them.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from wcdrive._util.history import DEFAULT_HISTORY
from wcdrive.host.boardclock import BoardClock
from wcdrive.host.odometry import OdometryEstimate, WheelOdometry
from wcdrive.protocol.codec import ExtendedTelemetry, Feedback
from wcdrive.protocol.spec import real

_log = logging.getLogger("wcdrive.telemetry")

__all__ = ["LinkEvent", "LinkLost", "LinkRestored", "Reset", "Telemetry", "TelemetryHub",
           "chair_wheel_angles"]


@dataclass(frozen=True)
class Telemetry:
    """One tick's feedback as the host received it."""

    time: float              # host monotonic time of arrival (s)
    count_left: int
    count_right: int
    vel_left: float          # rad/s, forward positive (the firmware un-mirrors the left wheel)
    vel_right: float
    mode: str
    extended: ExtendedTelemetry | None = None   # the TLM line of the same tick (after hello)
    #: The board's clock at the tick (s; continuous over resets) and the host time it
    #: maps to (``wcdrive.host.boardclock``): stamp navigation data with these.
    board_time: float | None = None
    stamp: float | None = None


#: One encoder count of the chair as a wheel angle (rad).
_RAD_PER_COUNT = 2.0 * math.pi / real("CPR")


def chair_wheel_angles(sample: Telemetry) -> tuple[float, float]:
    """The chair's wheel angles at ``sample`` (rad, forward positive; left, right): the
    left encoder counts mirrored. ``Robot.wheel_angles`` of every chair host."""
    return -sample.count_left * _RAD_PER_COUNT, sample.count_right * _RAD_PER_COUNT


@dataclass(frozen=True)
class LinkLost:
    """The board went silent: no line from it for ``silent_for`` s (more than the
    chair's ``link_timeout``), or its device vanished. Motion calls raise
    ``WcdriveConnectionError`` until ``LinkRestored``; the board's own watchdog stops
    the chair ``watchdog_ms`` after the last command it received."""

    time: float              # host monotonic time the loss was noticed (s)
    port: str                # the URL or device path
    silent_for: float        # seconds since the last line from the board
    reason: str              # "silent" (no lines) or "vanished" (the device went away)


@dataclass(frozen=True)
class LinkRestored:
    """Lines flow from the board again after a ``LinkLost`` (a reopened device too:
    the session then says hello again)."""

    time: float              # host monotonic time of the first line (s)
    port: str
    down_for: float          # seconds since the ``LinkLost``


@dataclass(frozen=True)
class Reset:
    """The board's counts (and clock) restarted: a board reset or a reopened device. The
    odometry re-baselined its counts and its pose carries on from ``pose``."""

    time: float              # host monotonic time of the first tick after it (s)
    board_time: float        # the board time it continues from (s)
    cause: str               # "boot" (seen by the session), "millis" (clock went back), "counts" (jumped)
    pose: tuple[float, float, float]   # the odometry's x, y, heading at the reset


#: What ``Wheelchair.on_link`` callbacks and ``telemetry(link_events=True)`` get.
LinkEvent = LinkLost | LinkRestored

#: rad/s of wheel speed beyond any the chair reaches: counts that move faster between
#: two ticks restarted (a board without ``TLM:``, or one whose clock did not go back).
_COUNT_JUMP_RAD_S = 40.0


def _offer(q: queue.Queue[Telemetry | LinkEvent], item: Telemetry | LinkEvent) -> None:
    """Puts ``item`` on a subscriber's bounded queue, dropping its oldest item when a
    reader that fell behind has filled it."""
    while True:
        try:
            q.put_nowait(item)
            return
        except queue.Full:
            try:
                q.get_nowait()
            except queue.Empty:
                pass
            _log.debug("telemetry: a reader fell behind; dropped its oldest item")


class TelemetryHub:
    """Keeps every tick's feedback, feeds the odometry, and fans out to subscribers."""

    def __init__(self, odometry_method: str = "position", history: int = DEFAULT_HISTORY) -> None:
        self._lock = threading.Lock()
        self._odometry = WheelOdometry(method=odometry_method)
        self.clock = BoardClock()
        self.resets: list[Reset] = []
        self._reset_callbacks: list[Callable[[Reset], None]] = []
        self._last_counts: tuple[int, int] | None = None
        #: The newest ``history`` ticks (``arrays``); a ring buffer.
        self._history: deque[tuple[float, int, int, float, float]] = deque(maxlen=history)
        self._subscribers: list[queue.Queue[Telemetry | LinkEvent]] = []
        self._link_subscribers: list[queue.Queue[Telemetry | LinkEvent]] = []
        self._callbacks: list[Callable[[Telemetry], None]] = []
        self._link_callbacks: list[Callable[[LinkEvent], None]] = []
        # Set by board_reset (the session saw the board restart): the next tick
        # re-baselines the odometry, so the pose carries on.
        self._rebase = False

    def deliver(self, now: float, msg: Feedback, extended: ExtendedTelemetry | None) -> None:
        """One tick arrived at host time ``now``: timed by the board's clock
        (``wcdrive.host.boardclock``); a restart of the counts re-baselines the odometry and
        sends a ``Reset``."""
        reset: Reset | None = None
        with self._lock:
            previous = self.clock.last
            sample = self.clock.update(now, extended.millis if extended is not None else None)
            # A reset the session saw (BOOT, reset on open: board_reset), or one the
            # board's clock shows (millis restarted), or counts that jumped.
            cause = "boot" if self._rebase else "millis" if sample.reset else None
            self._rebase = False
            if cause is None and self._last_counts is not None and previous is not None:
                limit = _COUNT_JUMP_RAD_S * max(sample.board - previous.board, self.clock.tick_period) \
                    * self._odometry.p.counts_per_rev / (2 * math.pi)
                if max(abs(msg.count_left - self._last_counts[0]),
                       abs(msg.count_right - self._last_counts[1])) > limit:
                    cause = "counts"
            if cause is not None:
                self._odometry.rebaseline()
                p = self._odometry.pose
                reset = Reset(now, sample.board, cause, (p.x, p.y, p.theta))
                self.resets.append(reset)
            self._last_counts = (msg.count_left, msg.count_right)
            self._odometry.update(sample.board, msg.count_left, msg.count_right)
            self._history.append((now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right))
            subscribers, callbacks = list(self._subscribers), list(self._callbacks)
            reset_callbacks = list(self._reset_callbacks)
        if reset is not None:
            for reset_cb in reset_callbacks:
                reset_cb(reset)
        t = Telemetry(now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right, msg.mode,
                      extended, sample.board, sample.host)
        for q in subscribers:
            _offer(q, t)
        for cb in callbacks:
            cb(t)

    def board_reset(self) -> None:
        """The board has reset (its counts start again from 0): the next tick re-bases
        the odometry's counts on the last ones, so that the pose carries on from where
        it was (the travel between the last tick and the reset is not seen). The raw
        counts in ``telemetry()`` and ``arrays()`` are the board's."""
        with self._lock:
            self._rebase = True

    def deliver_link(self, event: LinkEvent) -> None:
        """The link was lost or restored: to the ``on_link`` callbacks and the iterators
        that asked for link events."""
        with self._lock:
            subscribers, callbacks = list(self._link_subscribers), list(self._link_callbacks)
        for q in subscribers:
            _offer(q, event)
        for cb in callbacks:
            cb(event)

    def stream(self, closed: threading.Event, timeout: float | None = None) -> Iterator[Telemetry]:
        """Telemetry as it arrives, until ``closed`` is set or ``timeout`` s pass without any."""
        for item in self._stream(closed, timeout, link_events=False):
            assert isinstance(item, Telemetry)
            yield item

    def stream_with_link(self, closed: threading.Event, timeout: float | None = None
                         ) -> Iterator[Telemetry | LinkEvent]:
        """``stream``, with the ``LinkLost``/``LinkRestored`` events in their place
        among the ticks."""
        return self._stream(closed, timeout, link_events=True)

    def _stream(self, closed: threading.Event, timeout: float | None, link_events: bool
                ) -> Iterator[Telemetry | LinkEvent]:
        q: queue.Queue[Telemetry | LinkEvent] = queue.Queue(maxsize=self.history)
        with self._lock:
            self._subscribers.append(q)
            if link_events:
                self._link_subscribers.append(q)
        try:
            while not closed.is_set():
                try:
                    yield q.get(timeout=timeout)
                except queue.Empty:
                    return
        finally:
            with self._lock:
                self._subscribers.remove(q)
                if link_events:
                    self._link_subscribers.remove(q)

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        """Calls ``callback`` from the reader thread with every tick."""
        with self._lock:
            self._callbacks.append(callback)

    def on_reset(self, callback: Callable[[Reset], None]) -> None:
        """Calls ``callback`` with every ``Reset``, before the tick that shows it."""
        with self._lock:
            self._reset_callbacks.append(callback)

    def on_link(self, callback: Callable[[LinkEvent], None]) -> None:
        """Calls ``callback`` with every ``LinkLost``/``LinkRestored``."""
        with self._lock:
            self._link_callbacks.append(callback)

    @property
    def history(self) -> int:
        """How many ticks ``arrays`` keeps (the newest), and how many an iterator that
        is not read may queue before the oldest are dropped. Settable."""
        return self._history.maxlen or 0

    @history.setter
    def history(self, value: int) -> None:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"a history's bound must be an integer >= 1, not {value!r}")
        with self._lock:
            self._history = deque(self._history, maxlen=value)

    def arrays(self) -> dict[str, np.ndarray]:
        """The newest ``history`` ticks received, as numpy arrays."""
        with self._lock:
            rows = np.array(list(self._history), dtype=float).reshape(-1, 5)
        return {"time": rows[:, 0], "count_left": rows[:, 1].astype(np.int64),
                "count_right": rows[:, 2].astype(np.int64), "vel_left": rows[:, 3], "vel_right": rows[:, 4]}

    def odometry(self, at: float | None = None) -> OdometryEstimate:
        """The odometry stamped host time ``at`` (default: now), with the board time of
        its last tick and the host time that maps to."""
        with self._lock:
            estimate = self._odometry.estimate(time.monotonic() if at is None else at)
            last = self.clock.last
        if last is None:
            return estimate
        return dataclasses.replace(estimate, board_time=last.board, stamp=last.host)

    def odometry_stream(self, closed: threading.Event, rate_hz: float = 50.0) -> Iterator[OdometryEstimate]:
        """The odometry at ``rate_hz`` on a steady grid of host times, until ``closed``."""
        period = 1.0 / rate_hz
        next_at = time.monotonic()
        while not closed.is_set():
            next_at += period
            delay = next_at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -period:               # fell behind: skip, do not burst
                next_at += period * int(-delay / period)
            yield self.odometry(next_at)
