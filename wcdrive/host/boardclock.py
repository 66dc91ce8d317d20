"""The board's clock on the host: continuous board time from ``TLM:`` millis, and its
mapping to the host's clock.

A ``TLM:`` line carries the board's ``millis()`` at its control tick. ``BoardClock``

* unwraps it (``millis()`` is a 32-bit count that wraps after 49.7 days) and keeps it
  continuous over board resets: a ``millis`` that goes back (not a wrap) is a reset, and
  board time then carries on from where it was, advanced by the host time that passed
  (converted at the estimated rate);
* without ``TLM:`` (a protocol-v1 board), counts one ``tick_period`` per feedback line;
* maps board time to host time with a filter that tracks the offset and the drift of
  the two clocks (``ClockFilter``): a straight line fitted by least squares with
  exponential forgetting to (board, host arrival) pairs, lowered by the smallest
  residual of the recent lines, so that the mapped stamp is the earliest the host could
  have seen the tick (the transport's latency and the host's scheduling only ever add
  delay);
* keeps the stamps strictly increasing: each tick's host stamp is at least
  ``MIN_STAMP_STEP`` past the one before, even when the fit moves back, so a
  subscriber's stamps never go back.

A simulated board faster than the wall clock (``sim://?speed=4``) shows a rate of 0.25
host seconds per board second; one run as fast as simavr can, whatever rate it reaches.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from wcdrive.protocol.spec import integer

#: The control tick (s): the v1 boards' only clock, one feedback line per tick.
TICK_PERIOD = integer("CONTROL_PERIOD_MS") / 1000.0
_WRAP_MS = 1 << 32
#: The least a tick's host stamp moves past the one before (s): when the filter's fit
#: moves back (a lower latency floor, a new rate), the mapped time of the next tick can
#: be earlier than the last stamp; the stamp is then the last one plus this.
MIN_STAMP_STEP = 1e-6
#: A millis that goes back by less than this is a wrap only near the top of the range.
_WRAP_GUARD_MS = 60_000


class ClockFilter:
    """Host time as a linear function of board time: ``host = offset + rate * board``,
    least squares with forgetting ``time_constant`` samples, then lowered to the
    smallest residual over the last ``window`` samples (the latency floor)."""

    def __init__(self, time_constant: float = 200.0, window: int = 100) -> None:
        self._decay = 1.0 - 1.0 / time_constant
        self._origin: tuple[float, float] | None = None
        self._sw = self._sb = self._sh = self._sbb = self._sbh = 0.0
        self._residuals: deque[float] = deque(maxlen=window)
        self.samples = 0

    def add(self, board: float, host: float) -> None:
        """One line: the board's time ``board`` arrived at host time ``host`` (s)."""
        if self._origin is None:
            self._origin = (board, host)
        b, h = board - self._origin[0], host - self._origin[1]
        d = self._decay
        self._sw = d * self._sw + 1.0
        self._sb = d * self._sb + b
        self._sh = d * self._sh + h
        self._sbb = d * self._sbb + b * b
        self._sbh = d * self._sbh + b * h
        self.samples += 1
        self._residuals.append(host - self._line(board))

    @property
    def rate(self) -> float:
        """Host seconds per board second (1.0 until two samples)."""
        var = self._sbb / self._sw - (self._sb / self._sw) ** 2 if self._sw else 0.0
        if self.samples < 2 or var <= 1e-12:
            return 1.0
        cov = self._sbh / self._sw - (self._sb / self._sw) * (self._sh / self._sw)
        return cov / var

    def _line(self, board: float) -> float:
        if self._origin is None:
            return board
        b0, h0 = self._origin
        mb, mh = self._sb / self._sw, self._sh / self._sw
        return h0 + mh + self.rate * (board - b0 - mb)

    @property
    def offset(self) -> float:
        """Host time of board time 0 (s), on the latency floor."""
        return self.to_host(0.0)

    def to_host(self, board: float) -> float:
        """The host time of board time ``board`` (the latency floor of the fit)."""
        floor = min(self._residuals) if self._residuals else 0.0
        return self._line(board) + floor


@dataclass(frozen=True)
class ClockSample:
    """One tick's time: ``board`` (s, continuous over resets), ``host`` (the host time
    the filter maps it to), ``arrival`` (when the line reached the host) and ``reset``
    (the board reset just before this tick)."""

    board: float
    host: float
    arrival: float
    reset: bool


class BoardClock:
    """Board time from each tick's ``millis`` (or one ``tick_period`` a line without
    it) and its host time (module docstring)."""

    def __init__(self, tick_period: float = TICK_PERIOD, filter: ClockFilter | None = None) -> None:
        self.tick_period = tick_period
        self.filter = filter or ClockFilter()
        self._last_millis: int | None = None
        self._unwrapped = 0            # ms since the epoch's first millis, wraps included
        self._epoch = 0.0              # board s at the present epoch's millis 0
        self._last: ClockSample | None = None
        self.resets = 0

    @property
    def last(self) -> ClockSample | None:
        """The latest tick's time."""
        return self._last

    def update(self, arrival: float, millis: int | None) -> ClockSample:
        """One tick that reached the host at ``arrival`` (host s), with the board's
        ``millis`` (None for a board without ``TLM:``)."""
        reset = False
        if millis is None:
            board = self._last.board + self.tick_period if self._last else 0.0
        else:
            if self._last_millis is None:
                self._unwrapped = millis
                self._epoch = self._last.board - millis / 1000.0 + self._elapsed(arrival) \
                    if self._last else 0.0
            else:
                step = millis - self._last_millis
                if step < 0 and self._last_millis > _WRAP_MS - _WRAP_GUARD_MS and millis < _WRAP_GUARD_MS:
                    step += _WRAP_MS                          # the 32-bit wrap
                if step < 0:                                  # went back: the board reset
                    reset = True
                    self.resets += 1
                    assert self._last is not None
                    self._epoch = self._last.board + self._elapsed(arrival) - millis / 1000.0
                    self._unwrapped = millis
                else:
                    self._unwrapped += step
            self._last_millis = millis
            board = self._epoch + self._unwrapped / 1000.0
        self.filter.add(board, arrival)
        host = self.filter.to_host(board)
        if self._last is not None and host < self._last.host + MIN_STAMP_STEP:
            # the fit moved back (a new latency floor, a new rate): stamps still go forward
            host = self._last.host + MIN_STAMP_STEP
        sample = ClockSample(board, host, arrival, reset)
        self._last = sample
        return sample

    def _elapsed(self, arrival: float) -> float:
        """Board seconds since the last tick, from the host time that passed (at
        least a tick: board time moves forward)."""
        assert self._last is not None
        rate = self.filter.rate
        return max(self.tick_period, (arrival - self._last.arrival) / rate if rate > 0 else 0.0)

    def mark_reset(self) -> None:
        """The board reset (seen some other way, e.g. a ``BOOT:`` line or a reopened
        device): the next millis starts a new epoch, whether or not it went back."""
        if self._last_millis is not None:
            self._last_millis = None
            self.resets += 1

    def to_host(self, board: float) -> float:
        """The host time of board time ``board``."""
        return self.filter.to_host(board)
