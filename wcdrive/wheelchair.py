"""``Wheelchair``: one chair behind any serial-like link (a real port, the simulated
chair, the firmware in simavr through a pty, a CAN link), as ``wcdrive.connect``
returns it. The protocol (hello, framed lines, acknowledged requests, TLM) is handled
here; how the link is opened is ``wcdrive.api``'s business."""


from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import serial

from wcdrive.codec import (
    ESTOP,
    HELLO,
    RESET,
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
    encode_cmdvel,
    encode_get,
    encode_set,
    encode_wheel,
    frame,
)
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveEstopError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)
from wcdrive.odometry import OdometryEstimate, WheelOdometry


@dataclass(frozen=True)
class Telemetry:
    time: float              # host monotonic time of arrival (s)
    count_left: int
    count_right: int
    vel_left: float          # rad/s, forward positive (the firmware un-mirrors the left wheel)
    vel_right: float
    mode: str
    extended: ExtendedTelemetry | None = None   # the TLM line of the same tick (v2)


class _Request:
    def __init__(self) -> None:
        self.done = threading.Event()
        self.data: object | None = None
        self.reason: str | None = None


class Wheelchair:
    """A chair behind a serial-like ``port`` (``read``/``write``/``close``, pyserial's
    ``in_waiting``). ``reopen``: how to open the same device again after it vanished
    (device paths), tried for ``reconnect_timeout`` s."""

    REQUEST_TIMEOUT = 0.3
    REQUEST_TRIES = 4

    def __init__(self, port, *, odometry_method: str = "position",
                 on_close: Callable[[], None] | None = None,
                 reopen: Callable[[], object] | None = None, reconnect_timeout: float = 60.0,
                 ) -> None:
        self._port = port
        self._on_close = on_close
        self._reopen = reopen
        self.reconnect_timeout = reconnect_timeout
        self._decoder = LineDecoder()
        self._odometry = WheelOdometry(method=odometry_method)
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()
        self._history: list[tuple[float, int, int, float, float]] = []
        self._subscribers: list[queue.Queue] = []
        self._callbacks: list[Callable[[Telemetry], None]] = []
        self.errors: list[str] = []
        self.events: list[str] = []
        #: Protocol version the board answered hello with (1 until a v2 board does).
        self.protocol_version = 1
        self.firmware = ""
        self.status: ExtendedTelemetry | None = None
        self._hello = threading.Event()
        self._handshake_done = threading.Event()
        self._hello_sent_at = -1e9
        self._hello_tries = 0
        self._pending_feedback: tuple[float, Feedback] | None = None
        self._requests: dict[int, _Request] = {}
        self._last_data: object | None = None
        self._seq = 0
        self._estop_latched = False
        self._link_up = threading.Event()
        self._link_up.set()
        self._closed = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, name="wcdrive-reader", daemon=True)
        self._reader.start()

    # ---- commands ----------------------------------------------------------------
    def set_velocity(self, linear: float, angular: float) -> None:
        """Drive at ``linear`` m/s and ``angular`` rad/s (ValueError when out of range)."""
        self._move(encode_cmdvel(linear, angular))

    def set_wheels(self, left: float, right: float) -> None:
        """Wheel speeds in rad/s, forward positive."""
        self._move(encode_wheel(right, left))

    def stop(self) -> None:
        """Targets to zero at the normal ramp (also while the e-stop is latched)."""
        self._send(self._motion_line(encode_cmdvel(0.0, 0.0)))

    def estop(self) -> None:
        """Latch the e-stop: the board stops at its emergency rate and refuses motion
        until ``reset_estop()``. Acknowledged and retried; raises when the board never
        confirms (after sending a plain stop as well)."""
        if self.protocol_version < 2:
            self.stop()
            raise WcdriveProtocolError("this board speaks protocol v1, which has no latched "
                                       "e-stop: a stop was sent instead; flash the v2 firmware")
        self._estop_latched = True
        try:
            self._request(ESTOP.rstrip(b"\n"))
        except WcdriveTimeoutError:
            self.stop()
            raise

    def reset_estop(self, timeout: float = 5.0) -> None:
        """Release the e-stop once the chair has parked (the board refuses earlier: this
        waits and retries until ``timeout``). The chair stays at rest until a command."""
        if self.protocol_version < 2:
            raise WcdriveProtocolError("this board speaks protocol v1: there is no e-stop to reset")
        deadline = time.monotonic() + timeout
        while True:
            try:
                self._request(RESET.rstrip(b"\n"))
                self._estop_latched = False
                self.status = None          # the last TLM predates the reset
                return
            except WcdriveCommandError as exc:
                if exc.reason != "busy" or time.monotonic() > deadline:
                    raise
            time.sleep(0.05)

    @property
    def estop_latched(self) -> bool:
        if self.status is not None and self.status.estop_latched:
            return True
        return self._estop_latched

    def get_param(self, name: str) -> float:
        """A runtime parameter (protocol/PROTOCOL.md, "Parameters")."""
        return self._param(encode_get(name))

    def set_param(self, name: str, value: float) -> float:
        """Sets a parameter; returns the value now in force (as the board rounded it)."""
        return self._param(encode_set(name, value))

    def _param(self, command: bytes) -> float:
        if self.protocol_version < 2:
            raise WcdriveProtocolError("parameters need a protocol-v2 board")
        data = self._request(command)
        if not isinstance(data, Param):
            raise WcdriveProtocolError(f"expected a PAR: line, got {data!r}")
        return data.value

    def send_command(self, command: bytes) -> None:
        """Any protocol command (``encode_ppm(...)``, ``b"rp1.0,lp1.0,"``), framed with a
        checksum on a v2 board: for tools; navigation code uses the methods above."""
        self._move(command)

    @property
    def recording(self):
        """The session so far (``connect(..., record=True)``), a ``wcdrive.recording.Recording``."""
        recording = getattr(self._port, "recording", None)
        if recording is None:
            raise WcdriveProtocolError("not recording: connect(url, record=True)")
        return recording

    def _move(self, command: bytes) -> None:
        if self.estop_latched:
            raise WcdriveEstopError("the e-stop is latched: call reset_estop() once it is safe",
                                    "estop")
        self._send(self._motion_line(command))

    def _motion_line(self, command: bytes) -> bytes:
        """v2: checksummed (a corrupted byte is rejected by the board); v1: the seed form."""
        return frame(command) if self.protocol_version >= 2 else command

    def _request(self, command: bytes) -> object | None:
        """A sequenced line, resent until its ACK; returns the data line answered with it.
        Raises WcdriveCommandError on a NAK, WcdriveTimeoutError without an answer."""
        last_error = None
        for _ in range(self.REQUEST_TRIES):
            with self._lock:
                self._seq = (self._seq + 1) % 65536
                seq = self._seq
                request = self._requests[seq] = _Request()
            try:
                self._send(frame(command, seq))
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

    def _send(self, data: bytes) -> None:
        if self._closed.is_set():
            raise WcdriveConnectionError("the link is closed: connect() again")
        if not self._link_up.is_set():
            raise WcdriveConnectionError("the link is lost (unplugged?); reconnecting: the "
                                         "board's watchdog has stopped the chair")
        try:
            with self._write_lock:
                self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise WcdriveConnectionError(
                f"writing to the board failed ({exc}); is it still plugged in?") from exc

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
                self._port.write(HELLO)
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

    # ---- telemetry ------------------------------------------------------------------
    def wait_for_telemetry(self, timeout: float = 5.0) -> Telemetry:
        for t in self.telemetry(timeout=timeout):
            return t
        raise WcdriveTimeoutError(f"no feedback from the board in {timeout} s: is the firmware running?")

    def telemetry(self, timeout: float | None = None) -> Iterator[Telemetry]:
        """Feedback as it arrives; ends after ``timeout`` s without any."""
        q: queue.Queue = queue.Queue()
        with self._lock:
            self._subscribers.append(q)
        try:
            while not self._closed.is_set():
                try:
                    yield q.get(timeout=timeout)
                except queue.Empty:
                    return
        finally:
            with self._lock:
                self._subscribers.remove(q)

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        with self._lock:
            self._callbacks.append(callback)

    def telemetry_arrays(self) -> dict[str, np.ndarray]:
        """Everything received so far as numpy arrays."""
        with self._lock:
            rows = np.array(self._history, dtype=float).reshape(-1, 5)
        return {"time": rows[:, 0], "count_left": rows[:, 1].astype(np.int64),
                "count_right": rows[:, 2].astype(np.int64), "vel_left": rows[:, 3], "vel_right": rows[:, 4]}

    @property
    def odometry(self) -> OdometryEstimate:
        with self._lock:
            return self._odometry.estimate(time.monotonic())

    def odometry_stream(self, rate_hz: float = 50.0) -> Iterator[OdometryEstimate]:
        """The odometry estimate at ``rate_hz`` (50 Hz by default, as the guide's EKF
        expects), on a steady grid of times (``estimate.time``, host monotonic s): each
        estimate is extrapolated to its grid time from the latest encoder counts."""
        period = 1.0 / rate_hz
        next_at = time.monotonic()
        while not self._closed.is_set():
            next_at += period
            delay = next_at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -period:               # fell behind: skip, do not burst
                next_at += period * int(-delay / period)
            with self._lock:
                estimate = self._odometry.estimate(next_at)
            yield estimate

    def on_odometry(self, callback: Callable[[OdometryEstimate], None], rate_hz: float = 50.0
                    ) -> threading.Thread:
        """Calls ``callback`` with the odometry at ``rate_hz`` from a thread of its own,
        until the chair is closed."""
        def run() -> None:
            for estimate in self.odometry_stream(rate_hz):
                callback(estimate)

        thread = threading.Thread(target=run, name="wcdrive-odometry", daemon=True)
        thread.start()
        return thread

    # ---- the reader thread -----------------------------------------------------------
    def _read_loop(self) -> None:
        while not self._closed.is_set():
            try:
                data = self._port.read(max(1, self._port.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if self._closed.is_set() or not self._reconnect():
                    if not self._closed.is_set():
                        self.errors.append("link lost")
                    return
                continue
            if not data:
                continue
            now = time.monotonic()
            for msg in self._decoder.feed(data):
                self._handle(now, msg)

    def _handle(self, now: float, msg: object) -> None:
        if isinstance(msg, ExtendedTelemetry):
            self.status = msg
            if self._pending_feedback is not None:
                t, fb = self._pending_feedback
                self._pending_feedback = None
                self._deliver(t, fb, msg)
            return
        if self._pending_feedback is not None:      # a feedback line without its TLM
            t, fb = self._pending_feedback
            self._pending_feedback = None
            self._deliver(t, fb, None)
        if isinstance(msg, Feedback):
            if self.protocol_version >= 2:
                self._pending_feedback = (now, msg)  # its TLM line follows at once
            else:
                self._deliver(now, msg, None)
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
                self._estop_latched = True

    def _reconnect(self) -> bool:
        """The device vanished: reopen it until ``reconnect_timeout``; the board resets
        on open, so the handshake starts over."""
        if self._reopen is None:
            return False
        self._link_up.clear()
        self.events.append("LINK_LOST")
        try:
            self._port.close()
        except Exception:
            pass
        deadline = time.monotonic() + self.reconnect_timeout
        while not self._closed.is_set() and time.monotonic() < deadline:
            try:
                port = self._reopen()
            except Exception:
                time.sleep(0.25)
                continue
            self._port = port
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

    def _deliver(self, now: float, msg: Feedback, extended: ExtendedTelemetry | None) -> None:
        t = Telemetry(now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right, msg.mode,
                      extended)
        with self._lock:
            self._odometry.update(now, msg.count_left, msg.count_right)
            self._history.append((now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right))
            subscribers, callbacks = list(self._subscribers), list(self._callbacks)
        for q in subscribers:
            q.put(t)
        for cb in callbacks:
            cb(t)

    # ---- lifecycle -------------------------------------------------------------------
    def close(self) -> None:
        """Stops the chair, then closes the link. Safe to call twice."""
        if self._closed.is_set():
            return
        try:
            with self._write_lock:
                self._port.write(self._motion_line(encode_cmdvel(0.0, 0.0)))
                self._port.flush()
        except Exception:
            pass
        self._closed.set()
        try:
            self._port.close()
        finally:
            if self._on_close:
                self._on_close()

    def __enter__(self) -> Wheelchair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
