"""The serial session with one board: the reader thread, the hello handshake, the link's
liveness, reconnects, and sequenced requests, acknowledged, sent again only when the
board did not get them.

``Session`` speaks protocol v3 (``protocol/PROTOCOL.md``) over any ``Port``: every
line it writes is a frame ``$<seq>:<command>*<CCCC>\\n`` with its own sequence
number, from one counter (the hello, motion, requests, the last stop). It turns the
bytes the board sends into messages, hands each tick's feedback to a callback
(``wcdrive.host.telemetry.TelemetryHub.deliver``) and offers ``send_motion`` (a motion
command, framed, not awaited: its ``ACK:`` is ignored, a ``NAK:`` reason goes to
``errors``) and ``request`` (a frame whose answer is awaited, sent again only when the
board did not get it: a lost answer never makes the board act twice; see
``Session.request``). A second thread, the link monitor, watches the time since the
board's last line (``link_ok``, ``LinkLost``/``LinkRestored``) and paces the hello's
retries. The public API on top of it is ``wcdrive.Wheelchair``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TypeVar

import serial

from wcdrive._util.history import History
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveError,
    WcdriveEstopError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)
from wcdrive.host.requests import Request, RequestKind
from wcdrive.host.telemetry import LinkEvent, LinkLost, LinkRestored
from wcdrive.protocol.codec import (
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
    Unknown,
    encode_cmdvel,
    frame,
)
from wcdrive.protocol.spec import integer
from wcdrive.transports.port import Port

__all__ = ["PROTOCOL_VERSION", "FeedbackHandler", "Session"]

#: The protocol this host speaks, the spec's (``connect(url, legacy=True)`` also speaks v1).
PROTOCOL_VERSION = integer("PROTOCOL_VERSION")

#: Called from the reader thread with (host time, feedback, the TLM of the same tick).
FeedbackHandler = Callable[[float, Feedback, ExtendedTelemetry | None], None]

_log = logging.getLogger("wcdrive.session")


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
        #: The first TLM line that reports it (its ``seq``, or a later frame's): the
        #: board has parsed the line, so its answer, if none came, was lost.
        self.seen: ExtendedTelemetry | None = None


_V = TypeVar("_V")

#: ``_after_lost_answer``: the board did not act on the line; it may go out again.
_SEND_AGAIN = object()
#: ``_exchange``: a GET whose answer was lost: ask again, under a new number (the
#: board acted on the old one; a read never nests another request).
_ASK_AGAIN = object()
#: How many recent sequence numbers remember their send order (motion included).
_ORDER_MEMORY = 256
#: The stop every way out of a session sends.
_STOP = encode_cmdvel(0.0, 0.0)


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
    lost; ``on_link`` gets each ``LinkLost``/``LinkRestored``. ``board_clock``: for a
    simulated board, how far its output has come on its own clock (s; None when it
    cannot say: ``ThreadedBoard.reported_time``): the silence is then counted on that
    clock, so a board that runs faster or slower than the wall clock, or falls behind
    it on a loaded machine and hands its output over late, is silent only once its own
    time has run ``link_timeout`` past its last line."""

    REQUEST_TIMEOUT = 0.3
    REQUEST_TRIES = 4
    #: How long each hello waits for its answer before the next goes out: 3 tries,
    #: each waiting twice as long as the one before.
    HELLO_WAITS = (0.25, 0.5, 1.0)
    #: A refused hello is said again this long after the last, at the soonest: the next
    #: tick's answer budget (benchmarks/reliability.py R3 saw three ERR lines of a frame
    #: cut by a reset spend one, and the hellos sent at once went unanswered).
    HELLO_REFUSED_GAP = 0.06
    #: The link monitor woke this much later than it meant to: the whole process stood
    #: still (a GC pause, an overloaded machine), so silence then proves nothing yet.
    STALL = 0.02

    def __init__(self, port: Port, on_feedback: FeedbackHandler, *, name: str | None = None,
                 reopen: Callable[[], Port] | None = None, reconnect_timeout: float = 60.0,
                 legacy: bool = False, link_timeout: float = 0.15,
                 on_link: Callable[[LinkEvent], None] | None = None,
                 on_board_reset: Callable[[], None] | None = None,
                 board_clock: Callable[[], float | None] | None = None) -> None:
        self.port = port
        self._board_clock = board_clock
        self._on_board_reset = on_board_reset
        self.name = name or _port_name(port)
        self._on_feedback = on_feedback
        self._on_link = on_link
        self._reopen = reopen
        self.reconnect_timeout = reconnect_timeout
        self.legacy = legacy
        self.link_timeout = link_timeout
        self._decoder = LineDecoder()
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)   # a request was answered or seen
        # Reentrant: a signal handler or a finalizer may run on a thread in the middle
        # of a write and must still get its stop out.
        self._write_lock = threading.RLock()
        self._writing = False                  # a write is under way (interrupted: a partial line)
        #: Ring buffers of the newest ``DEFAULT_HISTORY`` items (``History``: a list
        #: whose ``maxlen`` is settable).
        self.errors: History[str] = History()
        self.events: History[str] = History()
        #: The protocol the board speaks: 3 once it answered hello, 1 in legacy mode
        #: once three hellos went unanswered, 0 until then.
        self.protocol_version = 0
        self.firmware = ""
        self.firmware_version = ""
        self.build_id = ""
        #: Why the handshake failed (``WcdriveProtocolError``), or None.
        self.handshake_error: WcdriveProtocolError | None = None
        #: The latest TLM line (after hello), or None.
        self.status: ExtendedTelemetry | None = None
        #: Set when the board announced an e-stop (``EVT:ESTOP``); cleared by a reset
        #: and when the link is reopened onto a board that has reset.
        self.estop_announced = False
        #: The host holds the e-stop latched (``Wheelchair.estop`` until ``reset_estop``):
        #: a board that reset meanwhile (a reconnect) gets ``estop`` right after hello.
        self.estop_held = False
        #: Faults the board announced (``EVT:FAULT,<name>``) since the last reset.
        self.faults_announced: History[str] = History()
        #: The cause of the board's last reset as its ``BOOT:`` line gave it ("" before one).
        self.reset_cause = ""
        #: What the board said of its parameters at its last boot: ``PARAMS_LOADED`` or
        #: ``PARAMS_DEFAULT,<why>`` ("" before such a line; a board without parameters in EEPROM sends none).
        self.params_at_boot = ""
        self._handshake_done = threading.Event()
        self._hello_tries = 0                   # hellos sent since the port was opened
        self._hello_sent_at = 0.0
        self._hello_seq = -1
        self._hello_rejected = False            # the board refused the last hello (ERR/NAK)
        self._hello_lock = threading.Lock()
        self._relatch_check = False             # the next TLM decides whether to re-latch
        self._pending_feedback: tuple[float, Feedback] | None = None
        self._requests: dict[int, _Request] = {}
        self._last_data: object | None = None
        self._seq = 0
        self._sends = 0
        self._sent_order: dict[int, int] = {}       # seq -> self._sends when it last went out
        self._motion_seqs: dict[int, None] = {}     # recent motion frames (their NAKs go to errors)
        self._telemetry_seen = False
        # liveness
        self._link_lock = threading.RLock()
        self._last_line_at: float | None = None     # host time of the board's last line
        self._last_line_board_at: float | None = None   # the board's clock then (board_clock)
        self._link_state: bool | None = None        # None: no line yet since construction
        self._lost_at = 0.0
        self._link_up = threading.Event()           # the port is there (cleared while reopening)
        self._link_up.set()
        self.closed = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, name="wcdrive-reader", daemon=True)
        self._monitor = threading.Thread(target=self._monitor_loop, name="wcdrive-link", daemon=True)
        self._reader.start()
        self._monitor.start()

    # ---- sending -------------------------------------------------------------------
    def _next_seq(self) -> int:
        """A fresh sequence number, 1 .. SEQ_MAX (a board that reset reports 0). Under
        ``_lock``."""
        self._seq = self._seq % SEQ_MAX + 1
        return self._seq

    def _register(self, seq: int) -> int:
        """Notes that the frame ``seq`` goes out now; returns its send order. Under
        ``_lock``, inside ``_write_lock`` (the send order is the order on the wire)."""
        self._sends += 1
        _remember(self._sent_order, seq, self._sends)
        return self._sends

    def send_frame(self, command: bytes, *, motion: bool = False) -> int:
        """Sends ``command`` without waiting, as a frame with a fresh sequence number
        registered in the send order (a TLM line that reports it proves that the frames
        before it arrived); returns the number. Its answer is ignored, but for the
        reason of a ``NAK:`` to a ``motion`` frame, which goes to ``errors``."""
        with self._write_lock:
            with self._lock:
                seq = self._next_seq()
                self._register(seq)
                if motion:
                    _remember(self._motion_seqs, seq, None)
            self._write(frame(command, seq))
        return seq

    def send_motion(self, command: bytes) -> int | None:
        """Sends a motion command (WHEEL, CMDVEL, PPM) without waiting: a v3 frame with
        its own sequence number (its ``ACK:`` is ignored, the reason of a ``NAK:`` goes
        to ``errors``); in legacy mode (v1) the bare seed form. Returns the sequence
        number (None in legacy mode). Raises ``WcdriveConnectionError`` when the port
        is closed, gone or the write fails."""
        if self.protocol_version == 1:
            self.send(command)
            return None
        return self.send_frame(command, motion=True)

    def send(self, data: bytes) -> None:
        """Writes ``data`` as it is; raises ``WcdriveConnectionError`` when the link is
        closed, lost or the write fails."""
        with self._write_lock:
            self._write(data)

    def _write(self, data: bytes) -> None:
        if self.closed.is_set():
            raise WcdriveConnectionError(f"the link to {self.name} is closed: connect() again")
        if not self._link_up.is_set():
            raise WcdriveConnectionError(f"the link to {self.name} is lost (unplugged?); reopening "
                                         "it: the board's watchdog has stopped the chair")
        self._writing = True
        try:
            self.port.write(data)
        except Exception as exc:                # pyserial's, the OS's, python-can's: name the port
            raise WcdriveConnectionError(
                f"writing to {self.name} failed ({exc}); is it still plugged in?") from exc
        finally:
            self._writing = False

    def request(self, request: Request) -> object | None:
        """``request`` as a frame whose answer is awaited; returns the data line answered with it
        (``PAR:``), or None. Raises WcdriveCommandError on a NAK (WcdriveEstopError for
        "estop"), WcdriveTimeoutError when the board never answers,
        WcdriveConnectionError when the link is lost meanwhile.

        The board acts on every frame it parses, a repeated one too, so the line
        goes out again (with the same sequence number) only when the board shows that
        it did not get it: for ``REQUEST_TIMEOUT`` s and two TLM lines, no TLM reported
        its number or that of a frame sent after it (motion frames count: they share
        the counter and the send order; a board without TLM lines:
        ``REQUEST_TIMEOUT`` s without an answer). When a TLM shows it parsed but its
        answer was lost (a corrupted byte on the way back, or the board's limit of 3
        answers a tick, which every frame uses, motion too), the outcome is read from
        the board instead of acting twice: the e-stop flag of that TLM for ESTOP and
        RESET, a GET for a SET (which goes out again only when the value in force is
        not the one asked for); a GET is asked again under a new number, up to
        ``REQUEST_TRIES`` times."""
        command = request.command
        for _ in range(self.REQUEST_TRIES):
            with self._lock:
                tracked = _Request(self._next_seq())
                self._requests[tracked.seq] = tracked
            try:
                result = self._exchange(request, tracked)
            finally:
                with self._lock:
                    self._requests.pop(tracked.seq, None)
            if result is not _ASK_AGAIN:
                return result
        raise WcdriveTimeoutError(f"no answer from {self.name} to {command.decode()!r} "
                                  f"in {self.REQUEST_TRIES} tries: is the link up?")

    def _exchange(self, request: Request, tracked: _Request, sent: bool = False) -> object | None:
        """Sends ``request`` as ``tracked`` (unless ``sent``: its first frame went out
        already) and awaits its outcome, sending it again while the board shows it did
        not get it."""
        command = request.command
        deadline = time.monotonic() + self.REQUEST_TIMEOUT * (self.REQUEST_TRIES + 1)
        for _ in range(self.REQUEST_TRIES):
            if not sent:
                self._send_request(command, tracked)
            sent = False
            outcome = self._await(tracked, deadline)
            if outcome == "answered":
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
            if outcome == "seen":
                result = self._after_lost_answer(request, tracked)
                if result is not _SEND_AGAIN:
                    return result
            elif outcome == "link":
                raise WcdriveConnectionError(
                    f"the link to {self.name} was lost while waiting for the answer to "
                    f"{command.decode()!r}: whether the board acted on it is unknown")
            elif outcome == "timeout":
                break
        raise WcdriveTimeoutError(f"no answer from {self.name} to {command.decode()!r}: "
                                  "is the link up?")

    def _send_request(self, command: bytes, request: _Request) -> None:
        data = frame(command, request.seq)
        with self._write_lock:                  # the send order is the order on the wire
            with self._lock:
                request.order, request.sent_at = self._register(request.seq), time.monotonic()
                request.ticks, request.seen = 0, None
                request.answered, request.data, request.reason = False, None, None
            self._write(data)

    def _await(self, request: _Request, deadline: float) -> str:
        """"answered", "seen" (the board has it, its answer was lost), "lost" (it
        did not get it), "link" (the link was lost) or "timeout"."""
        with self._changed:
            while True:
                if request.answered:
                    return "answered"
                if request.seen is not None:
                    return "seen"
                if self._link_state is False or self.closed.is_set():
                    return "link"
                now = time.monotonic()
                waited = now - request.sent_at >= self.REQUEST_TIMEOUT
                if waited and (request.ticks >= 2 or not self._telemetry_seen):
                    return "lost"
                if now >= deadline:
                    return "timeout"
                wake = deadline if waited else min(deadline, request.sent_at + self.REQUEST_TIMEOUT)
                self._changed.wait(wake - now)

    def _after_lost_answer(self, request: Request, tracked: _Request) -> object | None:
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

    # ---- handshake -------------------------------------------------------------------
    def _say_hello(self, now: float) -> None:
        """Sends the next hello (framed, with its own sequence number). Under
        ``_hello_lock``."""
        self._hello_tries += 1
        self._hello_sent_at = now
        self._hello_rejected = False
        try:
            self._hello_seq = self.send_frame(b"hello")
        except WcdriveConnectionError:
            pass

    def _hello_step(self, now: float, *, first: bool = False) -> float:
        """Says hello when the board first speaks (``first``), again when the last hello
        was refused (a garbled frame: ``ERR:``/``NAK:``) or went unanswered for its
        wait, and ends the handshake after the third. Called by the reader and by the
        link monitor; returns how long the monitor may sleep before it needs to look
        again."""
        with self._hello_lock:
            if self._handshake_done.is_set():
                return 0.05
            if self._hello_tries == 0:
                if first:
                    self._say_hello(now)
                    return self.HELLO_WAITS[0]
                return 0.05
            left = self._hello_sent_at + self.HELLO_WAITS[self._hello_tries - 1] - now
            if left > 0 and not self._hello_rejected:
                return left
            # A refused hello goes out again no sooner than a tick later: the board answers
            # 3 commands a tick, and the ERR lines of a frame cut by a reset can spend them.
            soon = self._hello_sent_at + self.HELLO_REFUSED_GAP - now
            if soon > 0:
                return soon
            if self._hello_tries < len(self.HELLO_WAITS):
                self._say_hello(now)
                return self.HELLO_WAITS[self._hello_tries - 1]
            if self.legacy:
                _log.info("%s: no answer to hello: driving it as a protocol-v1 board", self.name)
                self.protocol_version = 1
            else:
                self.handshake_error = WcdriveProtocolError(
                    f"{self.name} did not answer hello ({self._hello_tries} tries): it is not "
                    f"running protocol-v{PROTOCOL_VERSION} firmware. Flash it (wcdrive bench "
                    "flash), or connect(url, legacy=True) to drive a protocol-v1 board "
                    "without checksums, e-stop, parameters or telemetry")
            self._handshake_done.set()
            return 0.05

    def _hello_answered(self, msg: Hello) -> None:
        if msg.version != PROTOCOL_VERSION:
            if self.protocol_version == PROTOCOL_VERSION:
                return                          # a stray line; the board said v3 already
            self.handshake_error = WcdriveProtocolError(
                f"{self.name} speaks protocol v{msg.version} ({msg.firmware} "
                f"{msg.firmware_version}), which this wcdrive does not know: it speaks "
                f"v{PROTOCOL_VERSION}. Flash the firmware that comes with it "
                "(wcdrive bench flash) or install the wcdrive that matches the board")
            self._handshake_done.set()
            return
        self.protocol_version = msg.version
        self.handshake_error = None
        self.firmware, self.firmware_version, self.build_id = (
            msg.firmware, msg.firmware_version, msg.build_id)
        _log.info("%s: connected, protocol v%d, %s %s", self.name, msg.version, msg.firmware,
                  msg.firmware_version)
        if self.estop_held and not self._handshake_done.is_set():
            self._relatch_estop()
        self._handshake_done.set()

    def wait_for_handshake(self, timeout: float = 5.0) -> int:
        """Waits until the board answered hello; returns the protocol version (3, or 1
        in legacy mode after three hellos went unanswered). Raises
        ``WcdriveProtocolError`` when the board never answers hello (unless legacy) or
        answers with a version this host does not know, ``WcdriveTimeoutError`` when
        the handshake is still under way after ``timeout`` s (e.g. no line from the
        board yet)."""
        if not self._handshake_done.wait(timeout):
            raise WcdriveTimeoutError(
                f"no hello handshake with {self.name} in {timeout} s"
                + (": no line from the board at all; is the firmware running?"
                   if self._last_line_at is None else ""))
        if self.handshake_error is not None:
            raise WcdriveProtocolError(str(self.handshake_error))
        return self.protocol_version

    # ---- the reader thread -----------------------------------------------------------
    def _read_loop(self) -> None:
        while not self.closed.is_set():
            try:
                data = self.port.read(max(1, self.port.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if self.closed.is_set():
                    return
                self._link_change(False, time.monotonic(), "vanished")
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
            if messages:
                if self._board_clock is not None:
                    self._last_line_board_at = self._board_clock()
                self._last_line_at = now
                if self._link_state is not True:
                    self._link_change(True, now)
            for msg in messages:
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
            if self.protocol_version == PROTOCOL_VERSION:
                self._pending_feedback = (now, msg)  # its TLM line follows at once
            else:
                self._on_feedback(now, msg, None)
            self._hello_step(now, first=True)
        elif isinstance(msg, Boot):
            self.reset_cause = msg.cause
            if self._handshake_done.is_set() and self.protocol_version == PROTOCOL_VERSION:
                # A reset while the port stayed open (a brown-out, its watchdog, a
                # reset button): the board boots unpowered and lax; say hello again,
                # which also re-latches an e-stop the host holds.
                with self._hello_lock:
                    self._forget_board()
                self.events.append("BOARD_RESET")   # the cause: reset_cause
                _log.warning("%s: the board reset (%s)", self.name, msg.cause)
            self._hello_step(now, first=True)
        elif isinstance(msg, Hello):
            self._hello_answered(msg)
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
                    if isinstance(msg, Nak):
                        _log.info("%s: NAK of frame %d: %s", self.name, msg.seq, msg.reason)
                    self._changed.notify_all()
                elif isinstance(msg, Nak) and msg.seq in self._motion_seqs:
                    _log.warning("%s: NAK of motion frame %d: %s", self.name, msg.seq, msg.reason)
                    self.errors.append(msg.reason)
                elif isinstance(msg, Nak) and msg.seq == self._hello_seq:
                    self._hello_rejected = True
            self._last_data = None
            if self._hello_rejected:
                self._hello_step(now)
        elif isinstance(msg, Error):
            _log.warning("%s: the board refused a line: %s", self.name, msg.reason)
            self.errors.append(msg.reason)
            if not self._handshake_done.is_set() and self._hello_tries:
                self._hello_rejected = True         # a garbled hello: the next goes out now
                self._hello_step(now)
        elif isinstance(msg, Event):
            self.events.append(msg.name)
            if msg.name.startswith("PARAMS_"):
                self.params_at_boot = msg.name
            if msg.name == "ESTOP":
                _log.warning("%s: e-stop latched on the board", self.name)
                self.estop_announced = True
            elif msg.fault is not None:
                _log.error("%s: the board latched a fault: %s", self.name, msg.fault)
                self.faults_announced.append(msg.fault)
            else:
                _log.info("%s: board event %s", self.name, msg.name)
        elif isinstance(msg, Unknown):
            _log.info("%s: dropped a line that is none of the board's formats: %r",
                      self.name, msg.line[:80])

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
        if self._relatch_check:
            self._relatch_check = False
            if self.estop_held and not msg.estop_latched:
                self._relatch_estop()

    def _relatch_estop(self) -> None:
        """The host holds the e-stop but the board has not latched it (it reset, or the
        e-stop went out while the link was down): latch it there, as a request (sent
        again only when the board shows it did not get it). The first frame goes out at
        once, from this thread (the reader); a thread of its own awaits the answer."""
        request = Request.estop()
        with self._lock:
            tracked = _Request(self._next_seq())
            self._requests[tracked.seq] = tracked
        try:
            self._send_request(request.command, tracked)
        except WcdriveConnectionError:
            with self._lock:
                self._requests.pop(tracked.seq, None)
            self.errors.append("e-stop not re-sent")
            return

        def finish() -> None:
            try:
                self._exchange(request, tracked, sent=True)
            except WcdriveError as exc:
                self.errors.append(f"e-stop not re-latched: {exc}")
            finally:
                with self._lock:
                    self._requests.pop(tracked.seq, None)

        threading.Thread(target=finish, name="wcdrive-relatch", daemon=True).start()

    # ---- liveness ------------------------------------------------------------------------
    @property
    def link_ok(self) -> bool:
        """True while lines arrive from the board: the last less than
        ``link_timeout`` s ago."""
        return self._link_state is True and not self.closed.is_set()

    @property
    def since_last_line(self) -> float:
        """Seconds since the board's last line (inf before the first since the port
        was opened)."""
        last = self._last_line_at
        return float("inf") if last is None else time.monotonic() - last

    def _link_change(self, up: bool, now: float, reason: str = "silent",
                     silent_for: float | None = None) -> None:
        """The link came up or went down: note it (``events``) and tell ``on_link``,
        once per change. The first line after construction only sets ``link_ok``."""
        with self._link_lock:
            before = self._link_state
            if before is up or (before is None and not up) or self.closed.is_set():
                return
            self._link_state = up
            with self._changed:
                self._changed.notify_all()          # a request in flight gives up
            if before is None:
                return
            event: LinkEvent
            if up:
                event = LinkRestored(now, self.name, now - self._lost_at)
                _log.warning("%s: link restored after %.3f s", self.name, now - self._lost_at)
                self.events.append("LINK_RESTORED")
                if self.estop_held and self._handshake_done.is_set():
                    self._relatch_check = True      # an e-stop sent while it was down: check it
            else:
                self._lost_at = now
                last = self._last_line_at
                if silent_for is None:
                    silent_for = float("inf") if last is None else now - last
                event = LinkLost(now, self.name, silent_for, reason)
                _log.warning("%s: link lost (%s)", self.name, reason)
                self.events.append("LINK_LOST")
            if self._on_link is not None:
                try:
                    self._on_link(event)
                except Exception as exc:            # a subscriber's bug must not stop the link
                    _log.exception("%s: an on_link callback failed", self.name)
                    self.errors.append(f"on_link callback failed: {exc!r}")

    def _monitor_loop(self) -> None:
        """The link monitor: marks the link lost after ``link_timeout`` s without a
        line, and paces the hello's retries. The host's own stall is not the board's
        silence: when this thread wakes late (the process stood still) or the board's
        bytes wait unread in the port (the reader is behind), it looks again shortly
        instead. With a ``board_clock`` the silence is counted on the board's clock."""
        delay, planned = 0.0, time.monotonic()
        while not self.closed.wait(delay):
            now = time.monotonic()
            stalled = now - planned > self.STALL
            delay = self._hello_step(now)
            last = self._last_line_at
            if self._link_state is True and last is not None:
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
                    self._link_change(False, now, silent_for=silent)
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

    def _bytes_waiting(self) -> bool:
        """Whether the board's bytes wait unread in the port."""
        try:
            return int(self.port.in_waiting) > 0
        except Exception:
            return False

    def _reconnect(self) -> bool:
        """The device vanished: reopen it until ``reconnect_timeout``; the board resets
        on open, so the handshake starts over."""
        if self._reopen is None:
            return False
        self._link_up.clear()
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
            if self.closed.is_set():            # closed meanwhile: let the device go
                try:
                    port.close()
                except Exception:
                    pass
                return False
            self._decoder = LineDecoder()
            self._last_line_at = None
            self._board_clock = self._last_line_board_at = None   # the old board's clock
            self._forget_board()
            self._link_up.set()
            _log.warning("%s: reconnected", self.name)
            self.events.append("RECONNECTED")
            return True
        return False

    def _forget_board(self) -> None:
        """The board has reset (a reopened device, or a ``BOOT:`` line mid-session): what
        the host knew of it is gone, and the handshake starts over; ``on_board_reset``
        is told (the odometry re-bases its counts)."""
        if self._on_board_reset is not None:
            self._on_board_reset()
        self._pending_feedback = None
        self._last_data = None
        self.status = None                  # the old board's; the new one reports anew
        self.estop_announced = False        # re-latched after hello when estop_held
        self.faults_announced.clear()       # a board that reset has no fault latched
        self._telemetry_seen = False
        self._relatch_check = False
        self.protocol_version = 0
        self.handshake_error = None
        self._handshake_done.clear()
        self._hello_tries = 0
        self._hello_seq = -1

    # ---- lifecycle -------------------------------------------------------------------
    def stop_line(self) -> bytes:
        """The stop the session sends on its way out: a v3 frame (the bare seed form in
        legacy mode), preceded by a line end when a write was cut short (so that the
        board drops the partial line, not the stop). Takes no lock, so that a signal
        handler or a finalizer can call it on any thread at any moment."""
        seq = self._seq % SEQ_MAX + 1
        self._seq = seq
        line = _STOP + b"\n" if self.protocol_version == 1 else frame(_STOP, seq)
        return (b"\n" if self._writing else b"") + line

    def close(self, last_words: bytes = b"") -> None:
        """Writes ``last_words`` (best effort), then closes the port. Safe to call twice,
        from any thread (a signal handler, a finalizer)."""
        if self.closed.is_set():
            return
        locked = self._write_lock.acquire(timeout=0.5)
        try:
            if last_words:
                self.port.write(last_words)
            self.port.flush()
        except Exception:
            pass
        finally:
            if locked:
                self._write_lock.release()
        self.closed.set()
        with self._link_lock:
            self._link_state = False
        cancel = getattr(self.port, "cancel_read", None)
        try:
            if cancel is not None:
                cancel()                        # wake the reader's select at once
            self.port.close()
        except Exception:
            pass
        # The reader's select holds the device until it returns: wait for it, so that the
        # device (and its exclusive lock) is free when close() returns.
        if threading.current_thread() is not self._reader:
            self._reader.join(timeout=1.0)
