"""Request tracking on a live link: the waiting, the locking and the writing around
``wcdrive.protocol.exchange.Exchange``, which numbers every frame and decides what
each answer, and each lost one, means.

``RequestTracker.send_frame`` sends a frame without waiting; ``request`` sends a
``Request`` and awaits its answer, sending it again only when the board did not get
it, and reading the outcome back from the board when it got it but its answer was
lost. The reader thread feeds it the board's lines that concern it
(``note_data``, ``note_answer``, ``note_telemetry``), in the order they came.

Why this way: the rules (one counter for every frame, what a ``TLM:`` line proves,
what a lost answer means for each kind of request) are the exchange's, without I/O,
shared with ``wcdrive.testing.stepped.SteppedChair``; what is left here is what a
live link adds: the threads that wait, the lock around the exchange, the order on
the wire, the host's clock, and the errors raised.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable

from wcdrive._util.history import History
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveEstopError,
    WcdriveTimeoutError,
)
from wcdrive.host.requests import Request
from wcdrive.protocol.codec import Ack, ExtendedTelemetry, Hello, Nak, Param
from wcdrive.protocol.exchange import (
    Answered,
    Exchange,
    InFlight,
    MotionRefused,
    Next,
    Outcome,
    Verdict,
    answer_verdict,
    lost_answer_verdict,
    read_back_verdict,
)

__all__ = ["RequestTracker"]

_log = logging.getLogger("wcdrive.session")

#: ``_follow``: the board did not act on the line; it may go out again.
_SEND_AGAIN = object()
#: ``_exchange``: a GET whose answer was lost: ask again, under a new number (the
#: board acted on the old one; a read never nests another request).
_ASK_AGAIN = object()
#: ``_await``: the link was lost, or the deadline passed.
_LINK = object()
_TIMEOUT = object()


class RequestTracker:
    """Numbers, sends and follows the frames to the board named ``name``.

    ``write`` puts bytes on the wire; ``write_lock`` is held around each write and
    the send order noted with it (so the send order is the order on the wire).
    ``link_lost`` says whether the link is down or closed (a request in flight then
    gives up); call ``wake`` when that changes. The reasons of ``NAK:`` answers to
    motion frames go to ``errors``. Its lock guards the exchange (``Exchange``: the
    numbering, the requests in flight, the send order); ``request`` waits on it, the
    reader thread notes lines under it."""

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
        self._core = Exchange()

    # ---- numbering and sending ---------------------------------------------------------
    def next_seq_unlocked(self) -> int:
        """A fresh sequence number taken without the lock, for the last stop (a signal
        handler or a finalizer may need it on any thread at any moment)."""
        return self._core.next_seq()

    def send_frame(self, command: bytes, *, motion: bool = False) -> int:
        """Sends ``command`` without waiting, as a frame with a fresh sequence number
        registered in the send order; returns the number. Its answer is ignored, but
        for the reason of a ``NAK:`` to a ``motion`` frame, which goes to ``errors``."""
        with self._write_lock:
            with self._lock:
                seq, data = self._core.next_frame(command, motion=motion)
            self._write(data)
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

    def begin(self, request: Request) -> InFlight:
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

    def finish(self, request: Request, tracked: InFlight, guard: threading.Lock | None = None,
               wanted: Callable[[], bool] | None = None) -> object | None:
        """The outcome of ``request``, sent by ``begin`` as ``tracked``, as ``request``
        would give it (raising as it does). ``wanted``: whether it is still to be sent
        again, asked under ``guard`` with the sending (None once it is not)."""
        try:
            return self._exchange(request, tracked, sent=True, guard=guard, wanted=wanted)
        finally:
            self._forget(tracked)

    def _open(self) -> InFlight:
        with self._lock:
            return self._core.open()

    def _forget(self, tracked: InFlight) -> None:
        with self._lock:
            self._core.close(tracked)

    def _exchange(self, request: Request, tracked: InFlight, sent: bool = False,
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
            if outcome is Outcome.ANSWERED:
                result = self._follow(request, answer_verdict(request.kind.value, request.param, tracked))
            elif outcome is Outcome.SEEN:
                assert tracked.seen is not None
                result = self._follow(request, lost_answer_verdict(request.kind.value, tracked.seen))
            elif outcome is _LINK:
                raise WcdriveConnectionError(
                    f"the link to {self.name} was lost while waiting for the answer to "
                    f"{command.decode()!r}: whether the board acted on it is unknown")
            elif outcome is _TIMEOUT:
                break
            else:                               # lost: the board did not get it
                continue
            if result is not _SEND_AGAIN:
                return result
        raise WcdriveTimeoutError(f"no answer from {self.name} to {command.decode()!r}: "
                                  "is the link up?")

    def _follow(self, request: Request, verdict: Verdict) -> object | None:
        """Carries out the exchange's ``verdict`` on ``request``: its result, or
        ``_SEND_AGAIN``/``_ASK_AGAIN``; raises when the board refused it."""
        if verdict.next is Next.RETURN:
            return verdict.value
        if verdict.next is Next.REFUSED:
            reason = verdict.reason or ""
            cls = WcdriveEstopError if reason == "estop" else WcdriveCommandError
            raise cls(f"{self.name} refused {request.command.decode()!r}: {reason}", reason)
        if verdict.next is Next.ASK_AGAIN:
            return _ASK_AGAIN
        if verdict.next is Next.READ_BACK:      # a set whose PAR: line was lost: read the
            return self.request(request.read_back())    # value (a get never nests)
        if verdict.next is Next.CHECK_BACK:
            current = self.request(request.read_back())
            return self._follow(request, read_back_verdict(request.text, current))
        return _SEND_AGAIN

    def _send(self, command: bytes, tracked: InFlight) -> None:
        with self._write_lock:                  # the send order is the order on the wire
            with self._lock:
                data = self._core.send(tracked, command, time.monotonic())
            self._write(data)

    def _await(self, tracked: InFlight, deadline: float) -> object:
        """Waits until the board answered ``tracked``, showed that it has it or that it
        did not get it (an ``Outcome``), the link was lost (``_LINK``), or ``deadline``
        (``_TIMEOUT``)."""
        with self._changed:
            while True:
                now = time.monotonic()
                outcome = self._core.outcome(tracked, now, self.REQUEST_TIMEOUT)
                if outcome in (Outcome.ANSWERED, Outcome.SEEN):
                    return outcome
                if self._link_lost():
                    return _LINK
                if outcome is Outcome.LOST:
                    return outcome
                if now >= deadline:
                    return _TIMEOUT
                patience_ends = tracked.sent_at + self.REQUEST_TIMEOUT
                wake = deadline if now >= patience_ends else min(deadline, patience_ends)
                self._changed.wait(wake - now)

    # ---- the board's lines (the reader thread) ----------------------------------------
    def note_data(self, msg: Hello | Param | None) -> None:
        """A data line (``PAR:``, ``HELLO:``): the answer to the ``ACK:`` that follows it
        at once; None: a line that is none (feedback)."""
        with self._lock:
            if msg is None:
                self._core.end_data()
            else:
                self._core.receive(msg)

    def note_answer(self, msg: Ack | Nak) -> bool:
        """An ``ACK:`` or ``NAK:``: answers the request of its number; returns whether
        it was a request's answer or a motion frame's ``NAK:`` (else the hello's, say)."""
        claimed = False
        with self._changed:
            for event in self._core.receive(msg):
                if isinstance(event, Answered):
                    claimed = True
                    if event.reason is not None:
                        _log.info("%s: NAK of frame %d: %s", self.name, event.seq, event.reason)
                    self._changed.notify_all()
                elif isinstance(event, MotionRefused):
                    claimed = True
                    _log.warning("%s: NAK of motion frame %d: %s", self.name, event.seq, event.reason)
                    self._errors.append(event.reason)
        return claimed

    def note_telemetry(self, msg: ExtendedTelemetry) -> None:
        """A TLM line reports the last sequence number the board parsed: the pending
        requests sent up to it have reached the board; the others count a tick."""
        with self._changed:
            self._core.receive(msg)
            self._changed.notify_all()

    def wake(self) -> None:
        """The link went up or down: a request in flight looks again (and gives up
        when it is lost)."""
        with self._changed:
            self._changed.notify_all()

    def forget_board(self) -> None:
        """The board has reset: a data line of the old one answers nothing, and its TLM
        lines are yet to come."""
        with self._lock:
            self._core.forget_board()
