"""Telemetry: what the board reports each tick, kept and fanned out to subscribers, and
the odometry computed from it.

``TelemetryHub.deliver`` is called by the session's reader thread for every feedback
line (with the ``TLM:`` line of the same tick after hello); iterators, callbacks,
the history arrays and the odometry all read from here. ``TelemetryHub.deliver_link``
gets the link's state changes (``LinkLost``, ``LinkRestored``) for the subscribers
that asked for them.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from wcdrive.odometry import OdometryEstimate, WheelOdometry
from wcdrive.protocol.codec import ExtendedTelemetry, Feedback

__all__ = ["LinkEvent", "LinkLost", "LinkRestored", "Telemetry", "TelemetryHub"]


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


#: What ``Wheelchair.on_link`` callbacks and ``telemetry(link_events=True)`` get.
LinkEvent = LinkLost | LinkRestored


class TelemetryHub:
    """Keeps every tick's feedback, feeds the odometry, and fans out to subscribers."""

    def __init__(self, odometry_method: str = "position") -> None:
        self._lock = threading.Lock()
        self._odometry = WheelOdometry(method=odometry_method)
        self._history: list[tuple[float, int, int, float, float]] = []
        self._subscribers: list[queue.Queue[Telemetry | LinkEvent]] = []
        self._link_subscribers: list[queue.Queue[Telemetry | LinkEvent]] = []
        self._callbacks: list[Callable[[Telemetry], None]] = []
        self._link_callbacks: list[Callable[[LinkEvent], None]] = []
        # The board's counts restart at 0 when it resets: the odometry gets them plus
        # this offset, re-based at the first tick after a reset so the pose carries on.
        self._count_offset = (0, 0)
        self._last_counts: tuple[int, int] | None = None
        self._rebase = False

    def deliver(self, now: float, msg: Feedback, extended: ExtendedTelemetry | None) -> None:
        """One tick arrived at host time ``now``."""
        t = Telemetry(now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right, msg.mode,
                      extended)
        with self._lock:
            if self._rebase and self._last_counts is not None:
                self._count_offset = (self._last_counts[0] - msg.count_left,
                                      self._last_counts[1] - msg.count_right)
            self._rebase = False
            counts = (msg.count_left + self._count_offset[0], msg.count_right + self._count_offset[1])
            self._last_counts = counts
            self._odometry.update(now, *counts)
            self._history.append((now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right))
            subscribers, callbacks = list(self._subscribers), list(self._callbacks)
        for q in subscribers:
            q.put(t)
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
            q.put(event)
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
        q: queue.Queue[Telemetry | LinkEvent] = queue.Queue()
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

    def on_link(self, callback: Callable[[LinkEvent], None]) -> None:
        """Calls ``callback`` with every ``LinkLost``/``LinkRestored``."""
        with self._lock:
            self._link_callbacks.append(callback)

    def arrays(self) -> dict[str, np.ndarray]:
        """Everything received so far as numpy arrays."""
        with self._lock:
            rows = np.array(self._history, dtype=float).reshape(-1, 5)
        return {"time": rows[:, 0], "count_left": rows[:, 1].astype(np.int64),
                "count_right": rows[:, 2].astype(np.int64), "vel_left": rows[:, 3], "vel_right": rows[:, 4]}

    def odometry(self, at: float | None = None) -> OdometryEstimate:
        """The odometry extrapolated to host time ``at`` (default: now)."""
        with self._lock:
            return self._odometry.estimate(time.monotonic() if at is None else at)

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
