"""``EddieRobot``: the host's side of the Eddie control board, with the navigation
surface of ``wcdrive.host.robot.Robot``.

The board speaks request/reply ASCII (docs/eddie.md): one command line ended by CR,
one reply line ended by CR. ``EddieRobot`` owns the port through one lock, so the
caller's commands and the poll thread's never interleave; it writes commands the way
Eddie's ROS drivers do (upper-case mnemonic, ``std::hex``-style lower-case hex, 32-bit
two's complement for negatives) and parses replies at fixed positions.

* ``set_velocity(v, w)``: the ROS driver's kinematics, ``((v -/+ w S/2) / R) /
  (2 pi / 36)`` positions per second, truncated toward zero as C++'s conversion does,
  sent as ``GOSPD`` only when the pair changes (every ``GOSPD`` re-seeds the board's
  position loop from its 0.5 s speed average, so resending the same pair at 10 Hz
  would disturb it). Beyond 32767 positions/s: ``ValueError``.
* Odometry: a thread polls ``DIST``, ``HEAD`` and ``SPD`` at ``poll_hz`` (25 Hz by
  default, at least 20) and integrates ``DIST`` with ``wcdrive.host.odometry.WheelOdometry``
  (positions, 36 per revolution, radius 0.0762 m, the configured separation), with its
  covariance. ``HEAD`` is kept as ``heading_deg`` but not used: the board computes it
  with its own constant (186 positions per turn, a 0.395 m separation) and whole degrees.
* Deadman: the board's 2011 firmware has no watchdog at all, and ``WATCH`` (a later
  firmware's) is off by default. So the host stops the robot itself: when no
  ``set_velocity`` came for ``deadman_s`` (0.5 s, the Mega's watchdog) while moving,
  the poll thread sends ``STOP 0``. Besides, ``connect`` sends ``WATCH 1`` (stop after
  1 s without any command, should the host die) and ignores the ``ERROR`` of a board
  that has no ``WATCH``.
* Connecting: ``VER`` is asked until the board answers (``boot_timeout``, 3 s), in case
  opening the port resets the Propeller; then ``RST`` (odometry starts at 0).
* Telemetry: each poll gives a ``wcdrive.host.telemetry.Telemetry`` (``count_left``/
  ``count_right`` are ``DIST``'s positions, not mirrored; speeds in rad/s from ``SPD``;
  ``mode`` is ``"eddie"``).
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable, Iterator

from wcdrive.eddie.geometry import POSITIONS_PER_REV, WHEEL_RADIUS, WHEEL_SEPARATION, ir_distance
from wcdrive.errors import WcdriveCommandError, WcdriveConnectionError, WcdriveTimeoutError
from wcdrive.host.odometry import OdometryEstimate, OdometryParams, WheelOdometry
from wcdrive.host.telemetry import Telemetry
from wcdrive.protocol.codec import MAX_ANGULAR, MAX_LINEAR
from wcdrive.transports.port import Port
from wcdrive.transports.recording import Recording, RecordingPort

#: How long the board may take to answer a command (the ROS driver waits 80 ms for
#: the first byte; a paced simulation adds its step).
REPLY_TIMEOUT = 0.3
#: Metres per unit of a PING))) reply: 512 clock cycles at 80 MHz of a round trip at 343 m/s.
PING_M_PER_UNIT = 512 / 80e6 * 343.0 / 2.0
RAD_PER_POSITION = 2.0 * math.pi / POSITIONS_PER_REV


def std_hex(value: int) -> str:
    """``std::hex << (int)value``: lower case, no leading zeros, negatives as 32-bit."""
    return format(value & 0xFFFFFFFF, "x")


def signed(text: str, bits: int) -> int:
    """A fixed-width hex field read as two's complement."""
    v = int(text, 16)
    return v - (1 << bits) if v >> (bits - 1) else v


def gospd_counts(linear: float, angular: float, separation: float = WHEEL_SEPARATION) -> tuple[int, int]:
    """Positions per second (left, right) for ``linear`` m/s and ``angular`` rad/s."""
    left = ((linear - angular * separation / 2.0) / WHEEL_RADIUS) / RAD_PER_POSITION
    right = ((linear + angular * separation / 2.0) / WHEEL_RADIUS) / RAD_PER_POSITION
    out = (math.trunc(left), math.trunc(right))
    if max(abs(out[0]), abs(out[1])) > 32767:
        raise ValueError(f"set_velocity({linear}, {angular}) needs more than 32767 positions/s")
    return out


class EddieRobot:
    """An Eddie board over ``port`` (module docstring)."""

    def __init__(self, port: Port, *, name: str = "eddie", wheel_separation: float = WHEEL_SEPARATION,
                 poll_hz: float = 25.0, deadman_s: float = 0.5, reply_timeout: float = REPLY_TIMEOUT,
                 watch: bool = True, boot_timeout: float = 3.0) -> None:
        if poll_hz < 20.0:
            raise ValueError("poll_hz must be at least 20")
        self._port = port
        self.name = name
        self.wheel_separation = wheel_separation
        self.poll_hz = poll_hz
        self.deadman_s = deadman_s
        self.reply_timeout = reply_timeout
        self._io = threading.Lock()
        self._state = threading.Lock()
        self._closed = threading.Event()
        self._odo = WheelOdometry(OdometryParams(wheel_radius=WHEEL_RADIUS, wheelbase=wheel_separation,
                                                 counts_per_rev=POSITIONS_PER_REV))
        self._odo_time = time.monotonic()
        self._subscribers: list[queue.Queue[Telemetry]] = []
        self._callbacks: list[Callable[[Telemetry], None]] = []
        self._link_ok = False
        self._sent: tuple[int, int] | None = None
        self._last_motion = 0.0
        self.heading_deg = 0
        self.events: list[str] = []
        self.latest: Telemetry | None = None
        self._port.write(b"\r\r\r")           # as the ROS driver: end any partial line (no reply)
        time.sleep(0.05)
        while self._port.in_waiting:
            self._port.read(self._port.in_waiting)
        self.firmware_version = self._first_reply(boot_timeout)
        self._link_ok = True
        self.command("RST")
        if watch:
            try:
                self.command("WATCH 1")
            except WcdriveCommandError:
                self.events.append("board has no WATCH: host deadman only")
        self._thread = threading.Thread(target=self._poll, name=f"eddie-poll {name}", daemon=True)
        self._thread.start()

    def _first_reply(self, boot_timeout: float) -> str:
        """``VER``, asked again until ``boot_timeout``: a Propeller that resets when its
        port opens takes about 1.5 s to boot from EEPROM (docs/eddie.md)."""
        deadline = time.monotonic() + boot_timeout
        while True:
            try:
                return self.command("VER")
            except WcdriveTimeoutError:
                if time.monotonic() > deadline:
                    raise

    # ---- the wire ---------------------------------------------------------------------
    def command(self, text: str) -> str:
        """Sends one command line; returns the reply without its CR. ``ERROR`` replies
        raise ``WcdriveCommandError``, no reply within ``reply_timeout`` raises
        ``WcdriveTimeoutError``."""
        with self._io:
            if self._closed.is_set() and text != "STOP 0":
                raise WcdriveConnectionError(f"{self.name} is closed: connect() again")
            self._port.write(text.encode("ascii") + b"\r")
            reply = bytearray()
            deadline = time.monotonic() + self.reply_timeout
            while not reply.endswith(b"\r"):
                if time.monotonic() > deadline:
                    self._link_ok = False
                    raise WcdriveTimeoutError(
                        f"{self.name}: no reply to {text!r} within {self.reply_timeout} s")
                reply += self._port.read(max(1, min(self._port.in_waiting, 64)))
        line = reply[:-1].decode("ascii", "replace")
        if line.startswith("ERROR"):
            raise WcdriveCommandError(f"{self.name}: {text!r} -> {line!r}", line)
        return line

    # ---- navigation surface ---------------------------------------------------------
    def set_velocity(self, linear: float, angular: float) -> None:
        """Drive at ``linear`` m/s, ``angular`` rad/s; call again at >= 2 Hz (deadman).
        A speed that is not finite or beyond ``command_limits`` is a ``ValueError``, and
        nothing is sent."""
        for what, value, limit in (("linear", linear, MAX_LINEAR), ("angular", angular, MAX_ANGULAR)):
            if not math.isfinite(value) or abs(value) > limit:
                raise ValueError(f"{what} {value!r} is not a finite speed within +-{limit}")
        if not self._link_ok:
            raise WcdriveConnectionError(f"{self.name}: the board does not answer")
        pair = gospd_counts(linear, angular, self.wheel_separation)
        with self._state:
            self._last_motion = time.monotonic()
            send = pair != self._sent
        if send:
            self.command(f"GOSPD {std_hex(pair[0])} {std_hex(pair[1])}")
            with self._state:
                self._sent = pair

    def stop(self) -> None:
        """``STOP 0``: motor power to zero at once (the source's zero-distance stop)."""
        self.command("STOP 0")
        with self._state:
            self._sent = None

    @property
    def odometry(self) -> OdometryEstimate:
        """The pose from ``DIST``, its speeds and covariances, at the last poll."""
        with self._state:
            return self._odo.estimate(self._odo_time)

    def wheel_angles(self, sample: Telemetry) -> tuple[float, float]:
        """The wheels' angles (rad, forward positive): the Eddie's position counts."""
        return sample.count_left * RAD_PER_POSITION, sample.count_right * RAD_PER_POSITION

    @property
    def command_limits(self) -> tuple[float, float]:
        """The protocol's limits, as the chair's (the Eddie's own, 32767 positions/s, is
        far beyond what it can do)."""
        return MAX_LINEAR, MAX_ANGULAR

    @property
    def link_ok(self) -> bool:
        """Whether the board answered the last poll."""
        return self._link_ok

    def telemetry(self, timeout: float | None = None) -> Iterator[Telemetry]:
        """Each poll's sample; ends after ``timeout`` s without one, or on close."""
        q: queue.Queue[Telemetry] = queue.Queue()
        with self._state:
            self._subscribers.append(q)
        try:
            while not self._closed.is_set():
                try:
                    yield q.get(timeout=timeout)
                except queue.Empty:
                    return
        finally:
            with self._state:
                self._subscribers.remove(q)

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        """Calls ``callback`` from the poll thread with each sample."""
        with self._state:
            self._callbacks.append(callback)

    # ---- Eddie's extras ------------------------------------------------------------
    def ping(self) -> list[float | None]:
        """Each PING))) pin's distance in metres (None: no echo, out of 18..2900)."""
        return [None if v == 0 else v * PING_M_PER_UNIT
                for v in (int(f, 16) for f in self.command("PING").split())]

    def adc(self) -> list[int]:
        """The eight ADC channels, 12-bit counts."""
        reply = self.command("ADC")
        return [int(reply[i:i + 3], 16) for i in range(0, 32, 4)]

    def ir_distances(self) -> list[float | None]:
        """The IR sensors on ADC channels 1..3 (left, centre, right) in metres, None
        when nothing is within their 0.10..0.80 m (``wcdrive.eddie.geometry.ir_distance``)."""
        counts = self.adc()
        return [ir_distance(counts[c]) for c in (1, 2, 3)]

    def travel(self, positions: int, speed: int) -> None:
        """``TRVL``: a straight move of ``positions`` at up to ``speed`` positions/s."""
        self.command(f"TRVL {std_hex(positions)} {std_hex(speed)}")

    def turn(self, degrees: int, speed: int) -> None:
        """``TURN``: rotate in place, clockwise for positive ``degrees``."""
        self.command(f"TURN {std_hex(degrees)} {std_hex(speed)}")

    @property
    def recording(self) -> Recording:
        """Every byte both ways, when connected with ``record=True``."""
        if not isinstance(self._port, RecordingPort):
            raise WcdriveConnectionError(f"{self.name} is not being recorded: connect(url, record=True)")
        return self._port.recording

    @property
    def protocol_version(self) -> int:
        """0: the Eddie's ASCII command set has no version of its own."""
        return 0

    @property
    def firmware(self) -> str:
        """The firmware's name."""
        return "eddie"

    @property
    def build_id(self) -> str:
        """``HWVER``'s reply."""
        return self.command("HWVER")

    def send_command(self, command: bytes) -> None:
        """Sends one raw command line (without its CR)."""
        self.command(command.decode("ascii"))

    # ---- the poll thread ------------------------------------------------------------
    def _poll(self) -> None:
        period = 1.0 / self.poll_hz
        next_time = time.monotonic()
        while not self._closed.is_set():
            try:
                self._poll_once()
                self._deadman()
            except WcdriveTimeoutError:
                self.events.append(f"{time.monotonic():.3f} no reply")
            except (WcdriveCommandError, WcdriveConnectionError, OSError, ValueError) as exc:
                if self._closed.is_set():
                    return
                self.events.append(f"{time.monotonic():.3f} {exc}")
            next_time += period
            self._closed.wait(max(0.0, next_time - time.monotonic()))

    def _poll_once(self) -> None:
        dist = self.command("DIST")
        head = self.command("HEAD")
        spd = self.command("SPD")
        now = time.monotonic()
        left, right = signed(dist[0:8], 32), signed(dist[9:17], 32)
        sample = Telemetry(time=now, count_left=left, count_right=right,
                           vel_left=signed(spd[0:4], 16) * RAD_PER_POSITION,
                           vel_right=signed(spd[5:9], 16) * RAD_PER_POSITION, mode="eddie")
        with self._state:
            self._link_ok = True
            self.heading_deg = signed(head[0:3], 12)
            self._odo.update(now, -left, right)        # WheelOdometry mirrors the left count
            self._odo_time = now
            self.latest = sample
            subscribers, callbacks = list(self._subscribers), list(self._callbacks)
        for q in subscribers:
            q.put(sample)
        for cb in callbacks:
            cb(sample)

    def _deadman(self) -> None:
        with self._state:
            fire = self._sent not in (None, (0, 0)) and time.monotonic() - self._last_motion > self.deadman_s
        if fire:
            self.stop()
            self.events.append(f"{time.monotonic():.3f} deadman: STOP 0 after {self.deadman_s} s of silence")

    # ---- lifecycle -----------------------------------------------------------------------
    def close(self) -> None:
        """Stops the robot (``STOP 0``), the poll thread, and closes the port. Safe twice."""
        if self._closed.is_set():
            return
        self._closed.set()
        try:
            self.command("STOP 0")
        except (WcdriveCommandError, WcdriveTimeoutError, OSError):
            pass
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=2.0)
        self._port.close()

    @property
    def closed(self) -> bool:
        """True once closed."""
        return self._closed.is_set()

    def __enter__(self) -> EddieRobot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
