"""Request tracking: the sequence numbers of every frame, the order they went out in,
and the requests in flight until their outcome is known.

``RequestTracker.send_frame`` sends a frame without waiting; ``request`` sends a
``Request`` and awaits its answer, sending it again only when the board did not get
it, and reading the outcome back from the board when it got it but its answer was
lost. The reader thread feeds it the board's lines that concern it
(``note_data``, ``note_answer``, ``note_telemetry``), in the order they came.

Why this way: the board acts on every frame it parses, a repeated one too, so a
request may go out again only when the board shows that it did not get it. Each
``TLM:`` line reports the last sequence number the board parsed; one counter numbers
every frame (the hello, motion, requests) and the send order is the order on the wire,
so a TLM line that reports a later frame proves that an earlier one arrived.
"""

from __future__ import annotations

import contextlib
import enum
import logging
import threading
import time
from collections.abc import Callable
from typing import TypeVar

from wcdrive._util.history import History
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveEstopError,
    WcdriveTimeoutError,
)
from wcdrive.host.requests import Request, RequestKind
from wcdrive.protocol.codec import SEQ_MAX, Ack, ExtendedTelemetry, Hello, Nak, Param, frame

__all__ = ["RequestTracker"]

_log = logging.getLogger("wcdrive.session")

_V = TypeVar("_V")

#: How many recent sequence numbers remember their send order (motion included).
_ORDER_MEMORY = 256
#: ``_after_lost_answer``: the board did not act on the line; it may go out again.
_SEND_AGAIN = object()
#: ``_exchange``: a GET whose answer was lost: ask again, under a new number (the
#: board acted on the old one; a read never nests another request).
_ASK_AGAIN = object()


def _remember(recent: dict[int, _V], seq: int, value: _V) -> None:
    """Notes ``seq`` as the newest of ``recent``, which keeps the last ``_ORDER_MEMORY``."""
    recent.pop(seq, None)
    recent[seq] = value
    if len(recent) > _ORDER_MEMORY:
        del recent[next(iter(recent))]


def _same_value(value: float, text: bytes) -> bool:
    """Whether ``value`` (as the board prints a parameter: 4 decimals) is ``text``."""
    try:
        wanted = float(text)
    except ValueError:
        return False
    return abs(value - wanted) <= 0.5e-4 + 1e-6 * abs(wanted)


class _Outcome(enum.Enum):
    """How the wait for a request's answer ended (``RequestTracker._await``)."""

    ANSWERED = "answered"
    SEEN = "seen"           # the board has it, its answer was lost
    LOST = "lost"           # the board did not get it
    LINK = "link"           # the link was lost
    TIMEOUT = "timeout"


class _InFlight:
    """A sequenced request in flight; the fields are guarded by the tracker's lock."""

    def __init__(self, seq: int) -> None:
        self.seq = seq
        self.answered = False
        self.data: object | None = None
        self.reason: str | None = None
        self.order = 0          # the tracker's send counter when it last went out (0: not yet)
        self.sent_at = 0.0      # host time of that send
        self.ticks = 0          # TLM lines since then that do not report it
        #: The first TLM line that reports it (its ``seq``, or a later frame's): the
        #: board has parsed the line, so its answer, if none came, was lost.
        self.seen: ExtendedTelemetry | None = None


class RequestTracker:
    """Numbers, sends and follows the frames to the board named ``name``.

    ``write`` puts bytes on the wire; ``write_lock`` is held around each write and
    the send order noted with it (so the send order is the order on the wire).
    ``link_lost`` says whether the link is down or closed (a request in flight then
    gives up); call ``wake`` when that changes. The reasons of ``NAK:`` answers to
    motion frames go to ``errors``. Its lock guards the requests in flight and the
    send order; ``request`` waits on it, the reader thread notes lines under it."""

    REQUEST_TIMEOUT = 0.3
    REQUEST_TRIES = 4

    def __init__(self, name: str, write: Callable[[bytes], None], write_lock: threading.RLock,
                 link_lost: Callable[[], bool], errors: History[str]) -> None:
        self.name = name
        self._write = write
        self._write_lock = write_lock
        self._link_lost = link_lost
        self._errors = errors
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)   # a request was answered or seen
        self._requests: dict[int, _InFlight] = {}
        self._last_data: object | None = None       # a data line, until the ACK it comes with
        self._seq = 0
        self._sends = 0
        self._sent_order: dict[int, int] = {}       # seq -> self._sends when it last went out
        self._motion_seqs: dict[int, None] = {}     # recent motion frames (their NAKs go to errors)
        self._telemetry_seen = False

    # ---- numbering and sending ---------------------------------------------------------
    def _next_seq(self) -> int:
        """A fresh sequence number, 1 .. SEQ_MAX (a board that reset reports 0). Under
        ``_lock``."""
        self._seq = self._seq % SEQ_MAX + 1
        return self._seq

    def next_seq_unlocked(self) -> int:
        """A fresh sequence number taken without the lock, for the last stop (a signal
        handler or a finalizer may need it on any thread at any moment)."""
        self._seq = self._seq % SEQ_MAX + 1
        return self._seq

    def _register(self, seq: int) -> int:
        """Notes that the frame ``seq`` goes out now; returns its send order. Under
        ``_lock``, inside ``write_lock`` (the send order is the order on the wire)."""
        self._sends += 1
        _remember(self._sent_order, seq, self._sends)
        return self._sends

    def send_frame(self, command: bytes, *, motion: bool = False) -> int:
        """Sends ``command`` without waiting, as a frame with a fresh sequence number
        registered in the send order; returns the number. Its answer is ignored, but
        for the reason of a ``NAK:`` to a ``motion`` frame, which goes to ``errors``."""
        with self._write_lock:
            with self._lock:
                seq = self._next_seq()
                self._register(seq)
                if motion:
                    _remember(self._motion_seqs, seq, None)
            self._write(frame(command, seq))
        return seq

    # ---- requests ----------------------------------------------------------------------
    def request(self, request: Request) -> object | None:
        """Sends ``request`` and awaits its answer: ``Session.request``."""
        command = request.command
        for _ in range(self.REQUEST_TRIES):
            tracked = self._open()
            try:
                result = self._exchange(request, tracked)
            finally:
                self._forget(tracked)
            if result is not _ASK_AGAIN:
                return result
        raise WcdriveTimeoutError(f"no answer from {self.name} to {command.decode()!r} "
                                  f"in {self.REQUEST_TRIES} tries: is the link up?")

    def begin(self, request: Request) -> _InFlight:
        """Sends the first frame of ``request`` now, on this thread; ``finish`` awaits
        its outcome. Raises ``WcdriveConnectionError`` when the write fails (nothing is
        left in flight then)."""
        tracked = self._open()
        try:
            self._send(request.command, tracked)
        except WcdriveConnectionError:
            self._forget(tracked)
            raise
        return tracked

    def finish(self, request: Request, tracked: _InFlight, guard: threading.Lock | None = None,
               wanted: Callable[[], bool] | None = None) -> object | None:
        """The outcome of ``request``, sent by ``begin`` as ``tracked``, as ``request``
        would give it (raising as it does). ``wanted``: whether it is still to be sent
        again, asked under ``guard`` with the sending (None once it is not)."""
        try:
            return self._exchange(request, tracked, sent=True, guard=guard, wanted=wanted)
        finally:
            self._forget(tracked)

    def _open(self) -> _InFlight:
        with self._lock:
            tracked = _InFlight(self._next_seq())
            self._requests[tracked.seq] = tracked
        return tracked

    def _forget(self, tracked: _InFlight) -> None:
        with self._lock:
            self._requests.pop(tracked.seq, None)

    def _exchange(self, request: Request, tracked: _InFlight, sent: bool = False,
                  guard: threading.Lock | None = None, wanted: Callable[[], bool] | None = None
                  ) -> object | None:
        """Sends ``request`` as ``tracked`` (unless ``sent``: its first frame went out
        already) and awaits its outcome, sending it again while the board shows it did
        not get it."""
        command = request.command
        deadline = time.monotonic() + self.REQUEST_TIMEOUT * (self.REQUEST_TRIES + 1)
        for _ in range(self.REQUEST_TRIES):
            if not sent:
                with guard if guard is not None else contextlib.nullcontext():
                    if wanted is not None and not wanted():
                        return None
                    self._send(command, tracked)
            sent = False
            outcome = self._await(tracked, deadline)
            if outcome is _Outcome.ANSWERED:
                if tracked.reason is not None:
                    cls = WcdriveEstopError if tracked.reason == "estop" else WcdriveCommandError
                    raise cls(f"{self.name} refused {command.decode()!r}: {tracked.reason}",
                              tracked.reason)
                if request.kind in (RequestKind.GET, RequestKind.SET):
                    data = tracked.data
                    if not isinstance(data, Param) or data.name != request.param:
                        if request.kind is RequestKind.SET:    # its PAR: line was lost: read
                            return self.request(request.read_back())   # the value (a get never nests)
                        return _ASK_AGAIN
                return tracked.data
            if outcome is _Outcome.SEEN:
                result = self._after_lost_answer(request, tracked)
                if result is not _SEND_AGAIN:
                    return result
            elif outcome is _Outcome.LINK:
                raise WcdriveConnectionError(
                    f"the link to {self.name} was lost while waiting for the answer to "
                    f"{command.decode()!r}: whether the board acted on it is unknown")
            elif outcome is _Outcome.TIMEOUT:
                break
        raise WcdriveTimeoutError(f"no answer from {self.name} to {command.decode()!r}: "
                                  "is the link up?")

    def _send(self, command: bytes, tracked: _InFlight) -> None:
        data = frame(command, tracked.seq)
        with self._write_lock:                  # the send order is the order on the wire
            with self._lock:
                tracked.order, tracked.sent_at = self._register(tracked.seq), time.monotonic()
                tracked.ticks, tracked.seen = 0, None
                tracked.answered, tracked.data, tracked.reason = False, None, None
            self._write(data)

    def _await(self, tracked: _InFlight, deadline: float) -> _Outcome:
        """Waits until the board answered ``tracked``, showed that it has it or that it
        did not get it, the link was lost, or ``deadline``."""
        with self._changed:
            while True:
                if tracked.answered:
                    return _Outcome.ANSWERED
                if tracked.seen is not None:
                    return _Outcome.SEEN
                if self._link_lost():
                    return _Outcome.LINK
                now = time.monotonic()
                waited = now - tracked.sent_at >= self.REQUEST_TIMEOUT
                if waited and (tracked.ticks >= 2 or not self._telemetry_seen):
                    return _Outcome.LOST
                if now >= deadline:
                    return _Outcome.TIMEOUT
                wake = deadline if waited else min(deadline, tracked.sent_at + self.REQUEST_TIMEOUT)
                self._changed.wait(wake - now)

    def _after_lost_answer(self, request: Request, tracked: _InFlight) -> object | None:
        """The board parsed the line but its answer never came: what it did, read from
        the board, or ``_SEND_AGAIN`` when it did not act on it."""
        seen = tracked.seen
        assert seen is not None
        if request.kind is RequestKind.ESTOP:
            return None if seen.estop_latched else _SEND_AGAIN
        if request.kind is RequestKind.RESET:
            if seen.estop_latched:              # reset answers NAK only when not parked
                raise WcdriveCommandError(f"{self.name} refused 'reset': busy", "busy")
            return None
        if request.kind is RequestKind.GET:
            return _ASK_AGAIN
        if request.kind is not RequestKind.SET:
            return _SEND_AGAIN
        current = self.request(request.read_back())
        if isinstance(current, Param) and _same_value(current.value, request.text):
            return current
        return _SEND_AGAIN

    # ---- the board's lines (the reader thread) ----------------------------------------
    def note_data(self, msg: Hello | Param | None) -> None:
        """A data line (``PAR:``, ``HELLO:``): the answer to the ``ACK:`` that follows it
        at once; None: a line that is none (feedback)."""
        self._last_data = msg

    def note_answer(self, msg: Ack | Nak) -> bool:
        """An ``ACK:`` or ``NAK:``: answers the request of its number; returns whether
        it was a request's answer or a motion frame's ``NAK:`` (else the hello's, say)."""
        claimed = True
        with self._changed:
            tracked = self._requests.get(msg.seq)
            if tracked is not None and not tracked.answered:
                tracked.answered = True
                tracked.data = self._last_data
                tracked.reason = msg.reason if isinstance(msg, Nak) else None
                if isinstance(msg, Nak):
                    _log.info("%s: NAK of frame %d: %s", self.name, msg.seq, msg.reason)
                self._changed.notify_all()
            elif isinstance(msg, Nak) and msg.seq in self._motion_seqs:
                _log.warning("%s: NAK of motion frame %d: %s", self.name, msg.seq, msg.reason)
                self._errors.append(msg.reason)
            else:
                claimed = False
        self._last_data = None
        return claimed

    def note_telemetry(self, msg: ExtendedTelemetry) -> None:
        """A TLM line reports the last sequence number the board parsed: the pending
        requests sent up to it have reached the board; the others count a tick."""
        self._last_data = None                  # a data line is followed by its ACK at once
        with self._changed:
            self._telemetry_seen = True
            reported = self._sent_order.get(msg.seq, 0)
            for tracked in self._requests.values():
                if tracked.order == 0 or tracked.answered or tracked.seen is not None:
                    continue
                if msg.seq == tracked.seq or reported > tracked.order:
                    tracked.seen = msg
                else:
                    tracked.ticks += 1
            self._changed.notify_all()

    def wake(self) -> None:
        """The link went up or down: a request in flight looks again (and gives up
        when it is lost)."""
        with self._changed:
            self._changed.notify_all()

    def forget_board(self) -> None:
        """The board has reset: a data line of the old one answers nothing, and its TLM
        lines are yet to come."""
        self._last_data = None
        self._telemetry_seen = False
