"""The serial session with one board: the reader thread, the hello handshake, reconnects,
and sequenced requests, acknowledged, sent again only when the board did not get them.

``Session`` speaks the protocol (``protocol/PROTOCOL.md``) over any ``Port``: it turns
the bytes the board sends into messages, hands each tick's feedback to a callback
(``wcdrive.telemetry.TelemetryHub.deliver``), and offers ``send`` (a line as it is),
``motion_line`` (framed with a checksum on a v2 board) and ``request`` (a sequenced
line, sent again only when the board did not get it: a lost answer never makes the
board act twice; see ``Session.request``). The public API on top of it is
``wcdrive.Wheelchair``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import serial

from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveEstopError,
    WcdriveTimeoutError,
)
from wcdrive.protocol.codec import (
    HELLO,
    SEQ_MAX,
    Ack,
    Boot,
    Error,
    Event,
    ExtendedTelemetry,
    Feedback,
    Hello,
    LineDecoder,
    Nak,
    Param,
    frame,
)
from wcdrive.transports.port import Port

__all__ = ["FeedbackHandler", "Session"]

#: Called from the reader thread with (host time, feedback, the TLM of the same tick).
FeedbackHandler = Callable[[float, Feedback, ExtendedTelemetry | None], None]


class _Request:
    """A sequenced request in flight; the fields are guarded by the session's lock."""

    def __init__(self, seq: int) -> None:
        self.seq = seq
        self.answered = False
        self.data: object | None = None
        self.reason: str | None = None
        self.order = 0          # the session's send counter when it last went out (0: not yet)
        self.sent_at = 0.0      # host time of that send
        self.ticks = 0          # TLM lines since then that do not report it
        #: The first TLM line that reports it (its ``seq``, or a later request's): the
        #: board has parsed the line, so its answer, if none came, was lost.
        self.seen: ExtendedTelemetry | None = None


#: ``_after_lost_answer``: the board did not act on the line; it may go out again.
_SEND_AGAIN = object()
#: How many recent sequence numbers remember their send order.
_ORDER_MEMORY = 256


def _same_value(value: float, text: bytes) -> bool:
    """Whether ``value`` (as the board prints a parameter: 4 decimals) is ``text``."""
    try:
        wanted = float(text)
    except ValueError:
        return False
    return abs(value - wanted) <= 0.5e-4 + 1e-6 * abs(wanted)


class Session:
    """The protocol over ``port``. ``reopen``: how to open the same device again after it
    vanished (device paths), tried for ``reconnect_timeout`` s."""

    REQUEST_TIMEOUT = 0.3
    REQUEST_TRIES = 4

    def __init__(self, port: Port, on_feedback: FeedbackHandler, *,
                 reopen: Callable[[], Port] | None = None, reconnect_timeout: float = 60.0) -> None:
        self.port = port
        self._on_feedback = on_feedback
        self._reopen = reopen
        self.reconnect_timeout = reconnect_timeout
        self._decoder = LineDecoder()
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)   # a request was answered or seen
        self._write_lock = threading.Lock()
        self.errors: list[str] = []
        self.events: list[str] = []
        #: Protocol version the board answered hello with (1 until a v2 board does).
        self.protocol_version = 1
        self.firmware = ""
        #: The latest TLM line (v2 boards).
        self.status: ExtendedTelemetry | None = None
        #: Set when the board announced an e-stop (``EVT:ESTOP``); cleared by a reset
        #: and when the link is reopened onto a board that has reset.
        self.estop_announced = False
        #: The host holds the e-stop latched (``Wheelchair.estop`` until ``reset_estop``):
        #: a board that reset meanwhile (a reconnect) gets ``estop`` right after hello.
        self.estop_held = False
        self._hello = threading.Event()
        self._handshake_done = threading.Event()
        self._hello_sent_at = -1e9
        self._hello_tries = 0
        self._pending_feedback: tuple[float, Feedback] | None = None
        self._requests: dict[int, _Request] = {}
        self._last_data: object | None = None
        self._seq = 0
        self._sends = 0
        self._sent_order: dict[int, int] = {}       # seq -> self._sends when it last went out
        self._telemetry_seen = False
        self._link_up = threading.Event()
        self._link_up.set()
        self.closed = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, name="wcdrive-reader", daemon=True)
        self._reader.start()

    # ---- sending -------------------------------------------------------------------
    def motion_line(self, command: bytes) -> bytes:
        """v2: checksummed (a corrupted byte is rejected by the board); v1: the seed form."""
        return frame(command) if self.protocol_version >= 2 else command

    def send(self, data: bytes) -> None:
        """Writes ``data`` as it is; raises ``WcdriveConnectionError`` when the link is
        closed, lost or the write fails."""
        with self._write_lock:
            self._write(data)

    def _write(self, data: bytes) -> None:
        if self.closed.is_set():
            raise WcdriveConnectionError("the link is closed: connect() again")
        if not self._link_up.is_set():
            raise WcdriveConnectionError("the link is lost (unplugged?); reconnecting: the "
                                         "board's watchdog has stopped the chair")
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise WcdriveConnectionError(
                f"writing to the board failed ({exc}); is it still plugged in?") from exc

    def request(self, command: bytes) -> object | None:
        """A sequenced line; returns the data line answered with it (``PAR:``), or None.
        Raises WcdriveCommandError on a NAK (WcdriveEstopError for "estop"),
        WcdriveTimeoutError when the board never answers.

        The board acts on every framed line it parses, a repeated one too, so the line
        goes out again (with the same sequence number) only when the board shows that
        it did not get it: for ``REQUEST_TIMEOUT`` s and two TLM lines, no TLM reported
        its number (a board without TLM lines: ``REQUEST_TIMEOUT`` s without an
        answer). When a TLM reports it but its answer was lost (a corrupted byte on the
        way back, or the board's limit of 3 answers a tick), the outcome is read from the
        board instead of acting twice: the e-stop flag of that TLM for ``estop`` and
        ``reset``, a ``get:`` for a parameter (a ``set:`` goes out again only when the
        value in force is not the one asked for)."""
        with self._lock:
            self._seq = self._seq % SEQ_MAX + 1     # 1 .. SEQ_MAX: a board that reset reports 0
            request = self._requests[self._seq] = _Request(self._seq)
        try:
            return self._exchange(command, request)
        finally:
            with self._lock:
                self._requests.pop(request.seq, None)

    def _exchange(self, command: bytes, request: _Request) -> object | None:
        deadline = time.monotonic() + self.REQUEST_TIMEOUT * (self.REQUEST_TRIES + 1)
        for _ in range(self.REQUEST_TRIES):
            self._send_request(command, request)
            outcome = self._await(request, deadline)
            if outcome == "answered":
                if request.reason is not None:
                    cls = WcdriveEstopError if request.reason == "estop" else WcdriveCommandError
                    raise cls(f"the board refused {command.decode()!r}: {request.reason}",
                              request.reason)
                if command.startswith((b"get:", b"set:")):
                    name = command[4:].partition(b"=")[0]
                    data = request.data
                    if not isinstance(data, Param) or data.name.encode() != name:
                        return self.request(b"get:" + name)        # its PAR: line was lost
                return request.data
            if outcome == "seen":
                result = self._after_lost_answer(command, request)
                if result is not _SEND_AGAIN:
                    return result
            elif outcome == "timeout":
                break
        raise WcdriveTimeoutError(f"no answer to {command.decode()!r}: is the link up?")

    def _send_request(self, command: bytes, request: _Request) -> None:
        data = frame(command, request.seq)
        with self._write_lock:                  # the send order is the order on the wire
            with self._lock:
                self._sends += 1
                request.order, request.sent_at = self._sends, time.monotonic()
                request.ticks, request.seen = 0, None
                self._sent_order.pop(request.seq, None)
                self._sent_order[request.seq] = request.order
                if len(self._sent_order) > _ORDER_MEMORY:
                    del self._sent_order[next(iter(self._sent_order))]
            self._write(data)

    def _await(self, request: _Request, deadline: float) -> str:
        """"answered", "seen" (the board has it, its answer was lost), "lost" (it
        did not get it) or "timeout"."""
        with self._changed:
            while True:
                if request.answered:
                    return "answered"
                if request.seen is not None:
                    return "seen"
                now = time.monotonic()
                waited = now - request.sent_at >= self.REQUEST_TIMEOUT
                if waited and (request.ticks >= 2 or not self._telemetry_seen):
                    return "lost"
                if now >= deadline:
                    return "timeout"
                wake = deadline if waited else min(deadline, request.sent_at + self.REQUEST_TIMEOUT)
                self._changed.wait(wake - now)

    def _after_lost_answer(self, command: bytes, request: _Request) -> object | None:
        """The board parsed the line but its answer never came: what it did, read from
        the board, or ``_SEND_AGAIN`` when it did not act on it."""
        seen = request.seen
        assert seen is not None
        if command == b"estop":
            return None if seen.estop_latched else _SEND_AGAIN
        if command == b"reset":
            if seen.estop_latched:              # reset answers NAK only when not parked
                raise WcdriveCommandError("the board refused 'reset': busy", "busy")
            return None
        if not command.startswith((b"get:", b"set:")):
            return _SEND_AGAIN
        name, _, text = command[4:].partition(b"=")
        current = self.request(b"get:" + name)
        if command.startswith(b"get:") or (isinstance(current, Param) and _same_value(current.value, text)):
            return current
        return _SEND_AGAIN

    # ---- handshake -------------------------------------------------------------------
    def _maybe_hello(self, now: float) -> None:
        """Say hello after the board boots (or, without a boot line, at its first
        feedback): every second until it answers, three times at most."""
        if self._hello.is_set() or self._hello_tries >= 3 or now - self._hello_sent_at < 1.0:
            return
        self._hello_sent_at = now
        self._hello_tries += 1
        try:
            with self._write_lock:
                self.port.write(HELLO)
        except (serial.SerialException, OSError):
            pass

    def wait_for_handshake(self, timeout: float = 5.0) -> int:
        """Waits until the board answered hello (v2) or three hellos went unanswered
        (v1); returns the protocol version."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._handshake_done.wait(0.05):
                break
            if self._hello_tries >= 3 and time.monotonic() - self._hello_sent_at > 1.0:
                break
        return self.protocol_version

    # ---- the reader thread -----------------------------------------------------------
    def _read_loop(self) -> None:
        while not self.closed.is_set():
            try:
                data = self.port.read(max(1, self.port.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if self.closed.is_set() or not self._reconnect():
                    if not self.closed.is_set():
                        self.errors.append("link lost")
                    return
                continue
            if not data:
                continue
            now = time.monotonic()
            for msg in self._decoder.feed(data):
                self._handle(now, msg)

    def _flush_feedback(self, extended: ExtendedTelemetry | None) -> None:
        if self._pending_feedback is not None:
            t, fb = self._pending_feedback
            self._pending_feedback = None
            self._on_feedback(t, fb, extended)

    def _handle(self, now: float, msg: object) -> None:
        if isinstance(msg, ExtendedTelemetry):
            self.status = msg
            self._last_data = None                  # a data line is followed by its ACK at once
            self._note_telemetry(msg)
            self._flush_feedback(msg)
            return
        self._flush_feedback(None)                  # a feedback line without its TLM
        if isinstance(msg, Feedback):
            self._last_data = None
            if self.protocol_version >= 2:
                self._pending_feedback = (now, msg)  # its TLM line follows at once
            else:
                self._on_feedback(now, msg, None)
            self._maybe_hello(now)
        elif isinstance(msg, Boot):
            self._maybe_hello(now)
        elif isinstance(msg, Hello):
            self.protocol_version = msg.version
            self.firmware = msg.firmware
            if self.estop_held and msg.version >= 2:
                self._relatch_estop()
            self._hello.set()
            self._handshake_done.set()
            self._last_data = msg
        elif isinstance(msg, Param):
            self._last_data = msg
        elif isinstance(msg, Ack | Nak):
            with self._changed:
                request = self._requests.get(msg.seq)
                if request is not None and not request.answered:
                    request.answered = True
                    request.data = self._last_data
                    request.reason = msg.reason if isinstance(msg, Nak) else None
                    self._changed.notify_all()
            self._last_data = None
        elif isinstance(msg, Error):
            self.errors.append(msg.reason)
            if (msg.reason == "syntax" and not self._hello.is_set()
                    and now - self._hello_sent_at < 0.5):
                self._hello_tries = 3               # a v1 board: hello is not a command
                self._handshake_done.set()
        elif isinstance(msg, Event):
            self.events.append(msg.name)
            if msg.name == "ESTOP":
                self.estop_announced = True

    def _note_telemetry(self, msg: ExtendedTelemetry) -> None:
        """A TLM line reports the last sequence number the board parsed: the pending
        requests sent up to it have reached the board; the others count a tick."""
        with self._changed:
            self._telemetry_seen = True
            reported = self._sent_order.get(msg.seq, 0)
            for request in self._requests.values():
                if request.order == 0 or request.answered or request.seen is not None:
                    continue
                if msg.seq == request.seq or reported > request.order:
                    request.seen = msg
                else:
                    request.ticks += 1
            self._changed.notify_all()

    def _relatch_estop(self) -> None:
        """The board reset while the host held the e-stop: latch it there again."""
        try:
            with self._write_lock:
                self.port.write(frame(b"estop"))
        except (serial.SerialException, OSError):
            self.errors.append("e-stop not re-sent")

    def _reconnect(self) -> bool:
        """The device vanished: reopen it until ``reconnect_timeout``; the board resets
        on open, so the handshake starts over."""
        if self._reopen is None:
            return False
        self._link_up.clear()
        self.events.append("LINK_LOST")
        try:
            self.port.close()
        except Exception:
            pass
        deadline = time.monotonic() + self.reconnect_timeout
        while not self.closed.is_set() and time.monotonic() < deadline:
            try:
                port = self._reopen()
            except Exception:
                time.sleep(0.25)
                continue
            self.port = port
            self._decoder = LineDecoder()
            self._pending_feedback = None
            self._last_data = None
            self.status = None                  # the old board's; the new one reports anew
            self.estop_announced = False        # re-latched after hello when estop_held
            self._telemetry_seen = False
            self.protocol_version = 1
            self._hello.clear()
            self._handshake_done.clear()
            self._hello_tries = 0
            self._hello_sent_at = -1e9
            self._link_up.set()
            self.events.append("RECONNECTED")
            return True
        return False

    # ---- lifecycle -------------------------------------------------------------------
    def close(self, last_words: bytes = b"") -> None:
        """Writes ``last_words`` (best effort), then closes the port. Safe to call twice."""
        if self.closed.is_set():
            return
        try:
            with self._write_lock:
                if last_words:
                    self.port.write(last_words)
                self.port.flush()
        except Exception:
            pass
        self.closed.set()
        self.port.close()
