"""The serial session with one board: the port and its reader thread, and the parts that
make the protocol, composed.

``Session`` speaks protocol v4 (``protocol/PROTOCOL.md``) over any ``Port``: every
line it writes is a frame ``$<seq>:<command>*<CCCC>\\n`` with its own sequence
number, from one counter (the hello, motion, requests, the last stop). It turns the
bytes the board sends into messages, hands each tick's feedback to a callback
(``wcdrive.host.telemetry.TelemetryHub.deliver``) and offers ``send_motion`` (a motion
command, framed, not awaited: its ``ACK:`` is ignored, a ``NAK:`` reason goes to
``errors``) and ``request`` (a ``Request`` whose answer is awaited, sent again only
when the board did not get it: a lost answer never makes the board act twice). The
public API on top of it is ``wcdrive.Wheelchair``.

The parts, one concern each: ``tracker`` (``RequestTracker``: sequence numbers, the
send order, requests, retries, lost answers), ``handshake`` (``Handshake``: hello and
the protocol version), ``link`` (``LinkMonitor``: liveness, ``LinkLost`` and
``LinkRestored``, on a thread of its own that also paces the hello's retries) and
``board`` (``BoardState``: what the board reported, and the e-stop the host holds)
and ``wire`` (``Wire``: the port, its writes, reopening it, closing it). The session
itself runs the reader thread, routes each message to the parts, starts over when the
board resets, and re-latches the e-stop the host holds when the board lost it.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import serial

from wcdrive._util.history import History
from wcdrive.errors import WcdriveConnectionError, WcdriveError, WcdriveProtocolError, WcdriveTimeoutError
from wcdrive.host.board_state import BoardState
from wcdrive.host.handshake import HELLO_COMMAND, PROTOCOL_VERSION, Handshake
from wcdrive.host.link_monitor import LinkMonitor
from wcdrive.host.requests import Request
from wcdrive.host.telemetry import LinkEvent
from wcdrive.host.tracker import RequestTracker
from wcdrive.host.wire import Wire
from wcdrive.protocol.codec import (
    Ack,
    Boot,
    Corrupt,
    Error,
    Event,
    ExtendedTelemetry,
    Feedback,
    Hello,
    LineDecoder,
    LineStats,
    Nak,
    Param,
    Unknown,
    frame,
)
from wcdrive.protocol.motion import velocity_command
from wcdrive.transports.port import Port

__all__ = ["PROTOCOL_VERSION", "FeedbackHandler", "Session"]

#: Called from the reader thread with (host time, feedback, the TLM of the same tick).
FeedbackHandler = Callable[[float, Feedback, ExtendedTelemetry | None], None]

_log = logging.getLogger("wcdrive.session")

#: The stop every way out of a session sends.
_STOP = velocity_command(0.0, 0.0)


def _port_name(port: object) -> str:
    """What a port calls itself: pyserial's ``name`` (the path or URL), else that of the
    port a wrapper (``RecordingPort``) holds, else its type."""
    for attr in ("name", "portstr"):
        value = getattr(port, attr, None)
        if isinstance(value, str) and value:
            return value
    inner = getattr(port, "port", None)
    if isinstance(inner, str) and inner:
        return inner
    if inner is not None and inner is not port:
        return _port_name(inner)
    return type(port).__name__


class Session:
    """The protocol over ``port``, named ``name`` (the URL or device path) in every
    error. ``reopen``: how to open the same device again after it vanished (device
    paths), tried for ``reconnect_timeout`` s. ``legacy``: when the board never answers
    hello, speak protocol v1 (unframed seed lines) instead of failing.
    ``link_timeout``: seconds without a line from the board before the link counts as
    lost; ``on_link`` gets each ``LinkLost``/``LinkRestored``. ``on_board_reset`` runs
    when the board has reset (the odometry re-bases its counts). ``board_clock``: for a
    simulated board, how far its output has come on its own clock (s; None when it
    cannot say: ``ThreadedBoard.reported_time``): the silence is then counted on that
    clock (``LinkMonitor``).

    Threads: the reader (``wcdrive-reader``, here), the link monitor (``link``'s) and,
    for an e-stop re-latched, one that awaits its answer. Locks: the wire's, around
    every write; the tracker's, the handshake's and the link monitor's, each over its
    own state."""

    def __init__(self, port: Port, on_feedback: FeedbackHandler, *, name: str | None = None,
                 reopen: Callable[[], Port] | None = None, reconnect_timeout: float = 60.0,
                 legacy: bool = False, link_timeout: float = 0.15,
                 on_link: Callable[[LinkEvent], None] | None = None,
                 on_board_reset: Callable[[], None] | None = None,
                 board_clock: Callable[[], float | None] | None = None) -> None:
        self.name = name or _port_name(port)
        self.reconnect_timeout = reconnect_timeout
        self._deliver = on_feedback
        self._on_board_reset = on_board_reset
        self._reopen = reopen
        self._line_stats = LineStats()
        self._decoder = LineDecoder(self._line_stats)
        self.wire = Wire(port, self.name)
        #: Set once the session is closed.
        self.closed = self.wire.closed
        #: Ring buffers of the newest ``DEFAULT_HISTORY`` items (``History``: a list
        #: whose ``maxlen`` is settable).
        self.errors: History[str] = History()
        self.events: History[str] = History()
        self._pending_feedback: tuple[float, Feedback] | None = None   # awaits its TLM line
        self.board = BoardState(self.name)
        self.link = LinkMonitor(
            self.name, self.closed, link_timeout=link_timeout, board_clock=board_clock,
            on_link=on_link, events=self.events, errors=self.errors,
            wake=self._wake_requests, on_restored=self._link_restored,
            pace=lambda now: self.handshake.step(now), bytes_waiting=self.wire.bytes_waiting)
        #: Held while the host decides to latch the e-stop again and sends it, and while
        #: ``Wheelchair.reset_estop`` lets go of it: a latch decided before the release
        #: goes out before the reset, none after it.
        self.estop_lock = threading.Lock()
        self.tracker = RequestTracker(self.name, self.wire.write, self.wire.lock,
                                      lambda: self.link.lost, self.errors)
        self.handshake = Handshake(self.name, lambda: self.tracker.send_frame(HELLO_COMMAND),
                                   self._greeted, legacy=legacy)
        #: ``BOOT:`` lines read from the board (each counted once the host has forgotten
        #: what it knew of the board before it), and the condition told of each
        self.boots = 0
        self._booted = threading.Condition()
        self._dispatch: dict[type, Callable[[float, Any], None]] = {
            ExtendedTelemetry: self._on_telemetry, Feedback: self._on_feedback,
            Boot: self._on_boot, Hello: self._on_hello, Param: self._on_param,
            Ack: self._on_answer, Nak: self._on_answer, Error: self._on_error,
            Event: self._on_event, Unknown: self._on_unknown, Corrupt: self._on_corrupt}
        self._reader = threading.Thread(target=self._read_loop, name="wcdrive-reader", daemon=True)
        self._reader.start()
        self.link.start()

    # ---- what the parts know -------------------------------------------------------
    @property
    def port(self) -> Port:
        """The port to the board (a new one after a reconnect)."""
        return self.wire.port

    @property
    def protocol_version(self) -> int:
        """The protocol the board speaks: 4 once it answered hello, 1 in legacy mode
        once three hellos went unanswered, 0 until then."""
        return self.handshake.protocol_version

    @property
    def link_stats(self) -> LineStats:
        """The board's lines so far (a copy): good, bad CRC, spliced and lost
        (``LineStats``; protocol v4 frames every line, so only then are bad and lost
        lines seen)."""
        return dataclasses.replace(self._line_stats)

    @property
    def link_ok(self) -> bool:
        """True while lines arrive from the board: the last less than
        ``link_timeout`` s ago."""
        return self.link.ok

    @property
    def link_timeout(self) -> float:
        """Seconds without a line from the board before the link counts as lost."""
        return self.link.link_timeout

    @link_timeout.setter
    def link_timeout(self, value: float) -> None:
        self.link.link_timeout = value

    @property
    def since_last_line(self) -> float:
        """Seconds since the board's last line (inf before the first since the port
        was opened)."""
        return self.link.since_last_line

    # ---- sending -------------------------------------------------------------------
    def require_link(self, what: str) -> None:
        """Raises when ``what`` cannot go out: the session is closed, the handshake
        failed, or the link is lost."""
        if self.closed.is_set():
            raise WcdriveConnectionError(f"the link to {self.name} is closed: connect() again")
        if self.handshake.error is not None:
            raise WcdriveProtocolError(str(self.handshake.error))
        if not self.link_ok:
            silent = self.since_last_line
            raise WcdriveConnectionError(
                f"the link to {self.name} is lost: "
                + ("no line from the board yet" if math.isinf(silent) else
                   f"no line from the board for {silent:.2f} s (link_timeout {self.link_timeout} s)")
                + f"; {what} not sent. The board's watchdog stops the chair; the link "
                "recovers by itself when its lines flow again (chair.link_ok)")

    def send_frame(self, command: bytes, *, motion: bool = False) -> int:
        """Sends ``command`` without waiting, as a frame with a fresh sequence number
        registered in the send order (a TLM line that reports it proves that the frames
        before it arrived); returns the number. Its answer is ignored, but for the
        reason of a ``NAK:`` to a ``motion`` frame, which goes to ``errors``."""
        return self.tracker.send_frame(command, motion=motion)

    def send_motion(self, command: bytes) -> int | None:
        """Sends a motion command (WHEEL, CMDVEL, PPM) without waiting: a v3 frame with
        its own sequence number (its ``ACK:`` is ignored, the reason of a ``NAK:`` goes
        to ``errors``); in legacy mode (v1) the bare seed form. Returns the sequence
        number (None in legacy mode). Raises ``WcdriveConnectionError`` when the port
        is closed, gone or the write fails."""
        if self.protocol_version == 1:
            self.send(command)
            return None
        return self.tracker.send_frame(command, motion=True)

    def send(self, data: bytes) -> None:
        """Writes ``data`` as it is; raises ``WcdriveConnectionError`` when the link is
        closed, lost or the write fails."""
        self.wire.send(data)

    def request(self, request: Request) -> object | None:
        """Sends ``request`` as a frame whose answer is awaited; returns the data line
        answered with it (``PAR:``), or None. Raises WcdriveCommandError on a NAK
        (WcdriveEstopError for "estop"), WcdriveTimeoutError when the board never
        answers, WcdriveConnectionError when the link is lost meanwhile.

        The board acts on every frame it parses, a repeated one too, so the line
        goes out again (with the same sequence number) only when the board shows that
        it did not get it: for ``RequestTracker.REQUEST_TIMEOUT`` s and two TLM lines,
        no TLM reported its number or that of a frame sent after it (motion frames
        count: they share the counter and the send order; a board without TLM lines:
        ``REQUEST_TIMEOUT`` s without an answer). When a TLM shows it parsed but its
        answer was lost (a corrupted byte on the way back, or the board's limit of 3
        answers a tick, which every frame uses, motion too), the outcome is read from
        the board instead of acting twice: the e-stop flag of that TLM for ESTOP and
        RESET, a GET for a SET (which goes out again only when the value in force is
        not the one asked for); a GET is asked again under a new number, up to
        ``RequestTracker.REQUEST_TRIES`` times."""
        return self.tracker.request(request)

    # ---- handshake -------------------------------------------------------------------
    def wait_for_handshake(self, timeout: float | None = 5.0) -> int:
        """Waits until the board answered hello; returns the protocol version (4, or 1
        in legacy mode after three hellos went unanswered). Raises
        ``WcdriveProtocolError`` when the board never answers hello (unless legacy) or
        answers with a version this host does not know, ``WcdriveTimeoutError`` when
        the handshake is still under way after ``timeout`` s (e.g. no line from the
        board yet)."""
        if not self.handshake.done.wait(timeout):
            raise WcdriveTimeoutError(
                f"no hello handshake with {self.name} in {timeout} s"
                + (": no line from the board at all; is the firmware running?"
                   if self.link.last_line_at is None else ""))
        if self.handshake.error is not None:
            raise WcdriveProtocolError(str(self.handshake.error))
        return self.protocol_version

    def wait_for_boot(self, seen: int, timeout: float | None = 5.0) -> int:
        """Waits until the host has read a ``BOOT:`` line past the first ``seen``
        (``boots`` before a reset the caller caused: a DTR pulse, a power cycle) and
        the handshake after it is done (None: no limit); returns the protocol version.
        Until the host has read that line, ``wait_for_handshake`` may return at once:
        the handshake before the reset is still done. Raises ``WcdriveTimeoutError``
        when no such line came within ``timeout`` s, or as ``wait_for_handshake`` does.

        It counts ``BOOT:`` lines: any reset read after ``seen`` was taken answers it (take
        ``seen`` once the handshake is done), and a reset whose ``BOOT:`` line was lost (it
        carries no CRC) or never sent (a reopened device) is not seen. In legacy mode
        (protocol 1) the board is not greeted again: it returns once the line is read."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._booted:
            if not self._booted.wait_for(lambda: self.boots > seen, timeout):
                raise WcdriveTimeoutError(f"no reset of {self.name} seen in {timeout} s "
                                          f"({self.boots} BOOT lines read, {seen} before)")
        return self.wait_for_handshake(None if deadline is None else max(0.0, deadline - time.monotonic()))

    # ---- the reader thread -----------------------------------------------------------
    def _read_loop(self) -> None:
        while not self.closed.is_set():
            try:
                data = self.wire.read()
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if self.closed.is_set():
                    return
                self.link.change(False, time.monotonic(), "vanished")
                if not self._reconnect():
                    if not self.closed.is_set():
                        _log.error("%s: link lost; the device did not come back", self.name)
                        self.errors.append("link lost")
                    return
                continue
            if not data:
                continue
            now = time.monotonic()
            messages = self._decoder.feed(data)
            # A line that fails its check is no sign of a working link: a run of them
            # ends in LinkLost as silence does.
            if any(type(msg) is not Corrupt for msg in messages):
                self.link.heard(now)
            for msg in messages:
                self._handle(now, msg)

    def _handle(self, now: float, msg: object) -> None:
        if not isinstance(msg, ExtendedTelemetry):
            self._flush_feedback(None)              # a feedback line without its TLM
        self._dispatch[type(msg)](now, msg)

    def _flush_feedback(self, extended: ExtendedTelemetry | None) -> None:
        if self._pending_feedback is not None:
            t, fb = self._pending_feedback
            self._pending_feedback = None
            self._deliver(t, fb, extended)

    def _on_telemetry(self, now: float, msg: ExtendedTelemetry) -> None:
        self.board.note_telemetry(msg)
        self.tracker.note_telemetry(msg)
        if self.board.estop_lost(msg):
            with self.estop_lock:
                if self.board.estop_held:
                    self._relatch_estop()
        self._flush_feedback(msg)

    def _on_feedback(self, now: float, msg: Feedback) -> None:
        self.tracker.note_data(None)
        if self.protocol_version == PROTOCOL_VERSION:
            self._pending_feedback = (now, msg)     # its TLM line follows at once
        else:
            self._deliver(now, msg, None)
        self.handshake.step(now, first=True)

    def _on_boot(self, now: float, msg: Boot) -> None:
        self.board.note_boot(msg)
        if self.handshake.done.is_set() and self.protocol_version == PROTOCOL_VERSION:
            # A reset while the port stayed open (a brown-out, its watchdog, a reset
            # button): the board boots unpowered and lax; say hello again, which also
            # re-latches an e-stop the host holds.
            with self.handshake.lock:
                self._forget_board()
            self.events.append("BOARD_RESET")       # the cause: reset_cause
            _log.warning("%s: the board reset (%s)", self.name, msg.cause)
        with self._booted:
            self.boots += 1
            self._booted.notify_all()
        self.handshake.step(now, first=True)

    def _on_hello(self, now: float, msg: Hello) -> None:
        self.handshake.answered(msg)
        if msg.lines_framed:
            self._decoder.framed = True         # from now on, only frames are believed
        self.tracker.note_data(msg)

    def _on_param(self, now: float, msg: Param) -> None:
        self.tracker.note_data(msg)

    def _on_answer(self, now: float, msg: Ack | Nak) -> None:
        claimed = self.tracker.note_answer(msg)
        if isinstance(msg, Nak) and not claimed:
            self.handshake.note_answer(now, msg.seq, msg.reason)
        else:
            self.handshake.note_answer(now, None)

    def _on_error(self, now: float, msg: Error) -> None:
        _log.warning("%s: the board refused a line: %s", self.name, msg.reason)
        self.errors.append(msg.reason)
        self.handshake.garbled(now)             # a garbled hello: the next goes out now

    def _on_event(self, now: float, msg: Event) -> None:
        self.events.append(msg.name)
        self.board.note_event(msg)

    def _on_corrupt(self, now: float, msg: Corrupt) -> None:
        _log.debug("%s: dropped a board line that failed its check%s: %r", self.name,
                   " (spliced)" if msg.spliced else "", msg.line[:80])

    def _on_unknown(self, now: float, msg: Unknown) -> None:
        _log.info("%s: dropped a line that is none of the board's formats: %r",
                  self.name, msg.line[:80])

    # ---- the e-stop the host holds -------------------------------------------------------
    def _greeted(self) -> None:
        """The board answered the handshake's hello: it boots without an e-stop."""
        with self.estop_lock:
            if self.board.estop_held:
                self._relatch_estop()

    def _link_restored(self) -> None:
        """Lines flow again: an e-stop sent while the link was down may not have
        arrived; the next TLM line says."""
        if self.handshake.done.is_set():
            self.board.check_estop_at_next_telemetry()

    def _wake_requests(self) -> None:
        self.tracker.wake()

    def _relatch_estop(self) -> None:
        """The host holds the e-stop but the board has not latched it (it reset, or the
        e-stop went out while the link was down): latch it there, as a request (sent
        again only when the board shows it did not get it, and while the host still
        holds it). The first frame goes out at once, from this thread (the reader; the
        caller holds ``estop_lock``); a thread of its own awaits the answer."""
        request = Request.estop()
        try:
            tracked = self.tracker.begin(request)
        except WcdriveConnectionError:
            self.errors.append("e-stop not re-sent")
            return

        def finish() -> None:
            try:
                self.tracker.finish(request, tracked, guard=self.estop_lock,
                                    wanted=lambda: self.board.estop_held)
            except WcdriveError as exc:
                self.errors.append(f"e-stop not re-latched: {exc}")

        threading.Thread(target=finish, name="wcdrive-relatch", daemon=True).start()

    # ---- the board starts over -------------------------------------------------------
    def _reconnect(self) -> bool:
        """The device vanished: reopen it until ``reconnect_timeout``; the board resets
        on open, so the handshake starts over."""
        if self._reopen is None or not self.wire.reopen(self._reopen, self.reconnect_timeout):
            return False
        self._decoder = LineDecoder(self._line_stats)
        self.link.reopened()
        self._forget_board()
        self.wire.restored()
        _log.warning("%s: reconnected", self.name)
        self.events.append("RECONNECTED")
        return True

    def _forget_board(self) -> None:
        """The board has reset (a reopened device, or a ``BOOT:`` line mid-session): what
        the host knew of it is gone, and the handshake starts over; ``on_board_reset``
        is told (the odometry re-bases its counts)."""
        if self._on_board_reset is not None:
            self._on_board_reset()
        self._pending_feedback = None
        self._decoder.framed = False
        self._decoder.resync()
        self.tracker.forget_board()
        self.board.forget()
        self.handshake.forget()

    # ---- lifecycle -------------------------------------------------------------------
    def stop_line(self) -> bytes:
        """The stop the session sends on its way out: a v3 frame (the bare seed form in
        legacy mode), preceded by a line end when a write was cut short (so that the
        board drops the partial line, not the stop). Takes no lock, so that a signal
        handler or a finalizer can call it on any thread at any moment."""
        seq = self.tracker.next_seq_unlocked()
        line = _STOP + b"\n" if self.protocol_version == 1 else frame(_STOP, seq)
        return (b"\n" if self.wire.writing else b"") + line

    def close(self, last_words: bytes = b"") -> None:
        """Writes ``last_words`` (best effort), then closes the port. Safe to call twice,
        from any thread (a signal handler, a finalizer)."""
        if self.closed.is_set():
            return
        self.wire.close(last_words)
        self.link.close()
        # The reader's select holds the device until it returns: wait for it, so that the
        # device (and its exclusive lock) is free when close() returns.
        if threading.current_thread() is not self._reader:
            self._reader.join(timeout=1.0)
