"""The serial session with one board: the reader thread, the hello handshake, reconnects,
and sequenced requests that are resent until acknowledged.

``Session`` speaks the protocol (``protocol/PROTOCOL.md``) over any ``Port``: it turns
the bytes the board sends into messages, hands each tick's feedback to a callback
(``wcdrive.telemetry.TelemetryHub.deliver``), and offers ``send`` (a line as it is),
``motion_line`` (framed with a checksum on a v2 board) and ``request`` (a sequenced
line, resent until its ACK). The public API on top of it is ``wcdrive.Wheelchair``.
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
    def __init__(self) -> None:
        self.done = threading.Event()
        self.data: object | None = None
        self.reason: str | None = None


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
        self._write_lock = threading.Lock()
        self.errors: list[str] = []
        self.events: list[str] = []
        #: Protocol version the board answered hello with (1 until a v2 board does).
        self.protocol_version = 1
        self.firmware = ""
        #: The latest TLM line (v2 boards).
        self.status: ExtendedTelemetry | None = None
        #: Set when the board announced an e-stop (``EVT:ESTOP``) or the host sent one.
        self.estop_announced = False
        self._hello = threading.Event()
        self._handshake_done = threading.Event()
        self._hello_sent_at = -1e9
        self._hello_tries = 0
        self._pending_feedback: tuple[float, Feedback] | None = None
        self._requests: dict[int, _Request] = {}
        self._last_data: object | None = None
        self._seq = 0
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
        if self.closed.is_set():
            raise WcdriveConnectionError("the link is closed: connect() again")
        if not self._link_up.is_set():
            raise WcdriveConnectionError("the link is lost (unplugged?); reconnecting: the "
                                         "board's watchdog has stopped the chair")
        try:
            with self._write_lock:
                self.port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise WcdriveConnectionError(
                f"writing to the board failed ({exc}); is it still plugged in?") from exc

    def request(self, command: bytes) -> object | None:
        """A sequenced line, resent until its ACK; returns the data line answered with it.
        Raises WcdriveCommandError on a NAK, WcdriveTimeoutError without an answer."""
        last_error = None
        for _ in range(self.REQUEST_TRIES):
            with self._lock:
                self._seq = (self._seq + 1) % 65536
                seq = self._seq
                request = self._requests[seq] = _Request()
            try:
                self.send(frame(command, seq))
                if request.done.wait(self.REQUEST_TIMEOUT):
                    if request.reason is not None:
                        cls = WcdriveEstopError if request.reason == "estop" else WcdriveCommandError
                        raise cls(f"the board refused {command.decode()!r}: {request.reason}",
                                  request.reason)
                    return request.data
                last_error = f"no answer to {command.decode()!r} in {self.REQUEST_TIMEOUT} s"
            finally:
                with self._lock:
                    self._requests.pop(seq, None)
        raise WcdriveTimeoutError(f"{last_error}, {self.REQUEST_TRIES} tries: is the link up?")

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
            self._flush_feedback(msg)
            return
        self._flush_feedback(None)                  # a feedback line without its TLM
        if isinstance(msg, Feedback):
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
            self._hello.set()
            self._handshake_done.set()
            self._last_data = msg
        elif isinstance(msg, Param):
            self._last_data = msg
        elif isinstance(msg, Ack | Nak):
            with self._lock:
                request = self._requests.get(msg.seq)
            if request is not None:
                request.data = self._last_data
                request.reason = msg.reason if isinstance(msg, Nak) else None
                request.done.set()
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
