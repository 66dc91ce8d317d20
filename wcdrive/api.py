"""``wcdrive.connect(url) -> Wheelchair``: what navigation code imports.

    import wcdrive
    with wcdrive.connect("sim://") as chair:            # the simulated chair (default)
        for _ in range(50):
            chair.set_velocity(0.5, 0.1)                # m/s, rad/s; send at >= 2 Hz
            time.sleep(0.1)
        print(chair.odometry.pose)
    # leaving the block stops the chair and closes the link

URLs: ``sim://[?speed=S&seed=N]`` (in process: the bit-exact port + pymunk plant),
``simavr://[path/to.elf]`` (the compiled firmware in simavr, through a pty, so the
real-port code path runs), or a device path such as ``/dev/ttyACM0``.

The firmware stops the chair when no valid command arrives for 500 ms: hold a
velocity by sending it again at 2 Hz or faster (as a ROS ``cmd_vel`` stream does).
"""

from __future__ import annotations

import queue
import threading
import time
import urllib.parse
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import serial

from wcdrive.codec import Error, Event, Feedback, LineDecoder, encode_cmdvel, encode_wheel
from wcdrive.errors import WcdriveConnectionError, WcdrivePermissionError, WcdriveTimeoutError
from wcdrive.odometry import OdometryEstimate, WheelOdometry


@dataclass(frozen=True)
class Telemetry:
    time: float              # host monotonic time of arrival (s)
    count_left: int
    count_right: int
    vel_left: float          # rad/s, forward positive (the firmware un-mirrors the left wheel)
    vel_right: float
    mode: str


class Wheelchair:
    def __init__(self, port, *, odometry_method: str = "position", on_close: Callable[[], None] | None = None
                 ) -> None:
        self._port = port
        self._on_close = on_close
        self._decoder = LineDecoder()
        self._odometry = WheelOdometry(method=odometry_method)
        self._lock = threading.Lock()
        self._history: list[tuple[float, int, int, float, float]] = []
        self._subscribers: list[queue.Queue] = []
        self._callbacks: list[Callable[[Telemetry], None]] = []
        self.errors: list[str] = []
        self.events: list[str] = []
        self._closed = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, name="wcdrive-reader", daemon=True)
        self._reader.start()

    # ---- commands ----------------------------------------------------------------
    def set_velocity(self, linear: float, angular: float) -> None:
        """Drive at ``linear`` m/s and ``angular`` rad/s (ValueError when out of range)."""
        self._send(encode_cmdvel(linear, angular))

    def set_wheels(self, left: float, right: float) -> None:
        """Wheel speeds in rad/s, forward positive."""
        self._send(encode_wheel(right, left))

    def stop(self) -> None:
        self._send(encode_cmdvel(0.0, 0.0))

    def _send(self, data: bytes) -> None:
        if self._closed.is_set():
            raise WcdriveConnectionError("the link is closed: connect() again")
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise WcdriveConnectionError(
                f"writing to the board failed ({exc}); is it still plugged in?") from exc

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

    def _read_loop(self) -> None:
        while not self._closed.is_set():
            try:
                data = self._port.read(max(1, self._port.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError):
                if not self._closed.is_set():
                    self.errors.append("link lost")
                return
            if not data:
                continue
            now = time.monotonic()
            for msg in self._decoder.feed(data):
                if isinstance(msg, Feedback):
                    self._deliver(now, msg)
                elif isinstance(msg, Error):
                    self.errors.append(msg.reason)
                elif isinstance(msg, Event):
                    self.events.append(msg.name)

    def _deliver(self, now: float, msg: Feedback) -> None:
        t = Telemetry(now, msg.count_left, msg.count_right, msg.vel_left, msg.vel_right, msg.mode)
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
            self._port.write(encode_cmdvel(0.0, 0.0))
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


def _open_serial(path: str) -> serial.Serial:
    try:
        port = serial.Serial(path, 115200, timeout=0.1)
    except serial.SerialException as exc:
        if isinstance(exc.__context__, PermissionError) or "Permission denied" in str(exc):
            raise WcdrivePermissionError(
                f"permission denied on {path}: add yourself to the dialout group "
                "(sudo usermod -aG dialout $USER, then log in again)") from exc
        raise WcdriveConnectionError(f"cannot open {path}: {exc}") from exc
    return port


def connect(url: str = "sim://", *, boot_timeout: float = 10.0, **options) -> Wheelchair:
    parts = urllib.parse.urlsplit(url)
    if parts.scheme == "sim":
        port = serial.serial_for_url("wcsim://" + (f"?{parts.query}" if parts.query else ""), timeout=0.1)
        chair = Wheelchair(port, **options)
    elif parts.scheme == "simavr":
        from hil.pty_board import PtyBoard

        elf = (parts.netloc + parts.path) or None
        board = PtyBoard(elf).start()
        chair = Wheelchair(_open_serial(board.path), on_close=board.stop, **options)
    elif parts.scheme == "" and url.startswith("/"):
        chair = Wheelchair(_open_serial(url), **options)
    else:
        raise ValueError(f"unsupported URL {url!r}: use sim://, simavr://[elf] or a device path")
    try:
        chair.wait_for_telemetry(boot_timeout)   # the Mega resets on open: wait for it
    except WcdriveTimeoutError:
        chair.close()
        raise
    return chair
