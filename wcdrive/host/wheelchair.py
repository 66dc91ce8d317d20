"""``Wheelchair``: the public API over one board, as ``wcdrive.connect`` returns it.

A façade only: the protocol lives in ``wcdrive.host.session.Session`` (reader thread, hello,
liveness, reconnect, acknowledged requests) and telemetry with odometry in
``wcdrive.host.telemetry.TelemetryHub``. How the link is opened is ``wcdrive.api``'s business.

Exit safety: every way a program lets go of a chair sends a stop (best effort) and
closes the port. ``close()`` and leaving a ``with`` block do; so does garbage
collection of a ``Wheelchair`` nobody closed and the end of the interpreter (one
``weakref.finalize`` per chair covers both, ``atexit`` included, so a
``KeyboardInterrupt`` that ends a script stops its chair too). ``SIGTERM`` and
``SIGHUP`` kill a Python process without running any of that, so the first chair made
in the main thread installs a handler for each of them whose action is still the
default one (``stop_on_signals=True``): it stops and closes every open chair, then
lets the signal kill the process as it would have (exit status -15 / 143). A handler
the program installed itself is left alone (it then owns the exit: raising
``SystemExit`` there is enough, or ``wcdrive.stop_all()``). SIGKILL cannot be caught:
the board's watchdog stops the chair ``watchdog_ms`` (500 ms) after the last command.
The machinery is ``wcdrive.host.exit_safety``'s.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Literal, overload

import numpy as np

from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveConnectionError,
    WcdriveError,
    WcdriveEstopError,
    WcdriveFaultError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)
from wcdrive.host.boardclock import BoardClock
from wcdrive.host.exit_safety import install_signal_handlers, register, stop_all
from wcdrive.host.handshake import PROTOCOL_VERSION
from wcdrive.host.neutral import refuse_unready_motion, wait_for_neutral
from wcdrive.host.odometry import OdometryEstimate
from wcdrive.host.requests import Request
from wcdrive.host.scan_feed import ScanFeed, ScanSource
from wcdrive.host.session import Session
from wcdrive.host.telemetry import (
    LinkEvent,
    LinkLost,
    LinkRestored,
    Reset,
    Telemetry,
    TelemetryHub,
    chair_wheel_angles,
)
from wcdrive.protocol.codec import MAX_ANGULAR, MAX_LINEAR, ExtendedTelemetry, LineStats, Param
from wcdrive.protocol.motion import velocity_command, wheel_command
from wcdrive.protocol.spec import integer
from wcdrive.transports.port import Port
from wcdrive.transports.recording import Recording, recording_of

if TYPE_CHECKING:                     # the host side loads no simulator
    from wcdrive.plant.lidar import LaserScan, Lidar

__all__ = ["LINK_TIMEOUT", "LinkEvent", "LinkLost", "LinkRestored", "Reset", "Telemetry", "Wheelchair",
           "install_signal_handlers", "stop_all"]

#: Default ``link_timeout``: three feedback periods (150 ms) without a line from the board.
LINK_TIMEOUT = 3 * integer("CONTROL_PERIOD_MS") / 1000.0


class Wheelchair:
    """A chair behind a serial-like ``port`` (a ``wcdrive.transports.port.Port``);
    ``wcdrive.connect(url)`` makes one and waits for the board's hello.

    - ``name``: the URL or device path errors name (default: the port's own name).
    - ``reopen``: how to open the same device again after it vanished (device paths),
      tried for ``reconnect_timeout`` s; the new board is greeted again (hello).
    - ``legacy``: a board that never answers hello is driven with protocol v1
      (``protocol_version`` 1) instead of raising ``WcdriveProtocolError``.
    - ``link_timeout``: seconds without any line from the board (it sends one every
      50 ms) before the link counts as lost (``link_ok`` False, a ``LinkLost``
      event, motion calls raise ``WcdriveConnectionError``); lines flowing again
      restore it (``LinkRestored``).
    - ``board_clock``: a simulated board's own clock (``ThreadedBoard.reported_time``,
      which ``connect`` passes for ``sim://`` and ``simavr://``): ``link_timeout`` is
      then seconds of the board's time, whatever its speed and however far behind the
      wall clock a loaded machine leaves it.
    - ``stop_on_signals``: install the ``SIGTERM``/``SIGHUP`` handler that stops every
      chair before the process dies (module docstring).
    - ``on_close`` runs after the port is closed.
    - ``scan_source``: the chair's lidar, where its scans come from (``connect`` passes
      a simulated board's ``BoardLidar``); ``scan`` and ``on_scan`` read them.
    """

    def __init__(self, port: Port, *, name: str | None = None, odometry_method: str = "position",
                 on_close: Callable[[], None] | None = None,
                 reopen: Callable[[], Port] | None = None, reconnect_timeout: float = 60.0,
                 legacy: bool = False, link_timeout: float = LINK_TIMEOUT,
                 stop_on_signals: bool = True,
                 board_clock: Callable[[], float | None] | None = None,
                 scan_source: ScanSource | None = None) -> None:
        self._hub = TelemetryHub(odometry_method)
        self._scans: ScanFeed | None = None
        if scan_source is not None:
            self._scans = ScanFeed(scan_source, self._hub.clock)
            self._hub.on_telemetry(self._scans.poll)
        self._session = session = Session(
            port, self._hub.deliver, name=name, reopen=reopen, reconnect_timeout=reconnect_timeout,
            legacy=legacy, link_timeout=link_timeout, on_link=self._hub.deliver_link,
            on_board_reset=self._hub.board_reset, board_clock=board_clock)
        self._finalizer = register(self, session, on_close)
        if stop_on_signals:
            install_signal_handlers()

    # ---- what the session knows ------------------------------------------------------
    @property
    def url(self) -> str:
        """The URL or device path of the board (what errors name)."""
        return self._session.name

    @property
    def protocol_version(self) -> int:
        """The protocol the board speaks: 4 once it answered hello, 1 in legacy mode
        after three hellos went unanswered, 0 until the handshake is over."""
        return self._session.protocol_version

    @property
    def firmware(self) -> str:
        """The firmware's name from its hello answer ("final_control"; "" before)."""
        return self._session.handshake.firmware

    @property
    def firmware_version(self) -> str:
        """The firmware's version from its hello answer ("3.0.0"; "" before)."""
        return self._session.handshake.firmware_version

    @property
    def build_id(self) -> str:
        """The firmware's build id from its hello answer (8 hex digits of the hash of
        its sources, ``wcdrive.protocol.spec.build_id``; "" before)."""
        return self._session.handshake.build_id

    @property
    def status(self) -> ExtendedTelemetry | None:
        """The latest ``TLM:`` line (after hello), or None."""
        return self._session.board.status

    @property
    def errors(self) -> list[str]:
        """Every ``ERR:`` reason the board sent, the reasons of the ``NAK:`` answers to
        motion commands, and "link lost"."""
        return self._session.errors

    @property
    def history_limit(self) -> int:
        """How many items each history keeps, the newest (``errors``, ``events``,
        ``telemetry_arrays``, and what an unread ``telemetry()`` iterator queues): ring
        buffers, 10,000 by default. Settable: ``chair.history_limit = 100_000``."""
        return self._session.errors.maxlen

    @history_limit.setter
    def history_limit(self, value: int) -> None:
        self._hub.history = value
        for history in (self._session.errors, self._session.events, self._session.board.faults_announced):
            history.maxlen = value

    @property
    def events(self) -> list[str]:
        """Every ``EVT:`` the board sent, and the link's: LINK_LOST, LINK_RESTORED,
        RECONNECTED (a vanished device was reopened)."""
        return self._session.events

    @property
    def reconnect_timeout(self) -> float:
        """Seconds a vanished device is reopened for."""
        return self._session.reconnect_timeout

    @reconnect_timeout.setter
    def reconnect_timeout(self, value: float) -> None:
        self._session.reconnect_timeout = value

    # ---- the link ----------------------------------------------------------------------
    def wheel_angles(self, sample: Telemetry) -> tuple[float, float]:
        """The wheels' angles (rad, forward positive): the left encoder counts mirrored."""
        return chair_wheel_angles(sample)

    @property
    def command_limits(self) -> tuple[float, float]:
        """The protocol's limits (m/s, rad/s)."""
        return MAX_LINEAR, MAX_ANGULAR

    @property
    def link_ok(self) -> bool:
        """True while the board's lines arrive: the last less than ``link_timeout`` s
        ago (False before the first line, after ``close()``, while the device is gone)."""
        return self._session.link_ok

    @property
    def link_stats(self) -> LineStats:
        """The board's lines so far (a copy): ``good`` (believed), ``bad_crc`` (failed
        their check: dropped), ``spliced`` (two lines joined where bytes were lost:
        dropped) and ``lost`` (sent, says the line counter, but never seen). Protocol v4
        frames every line, so this counts every line the board sent since hello; a
        dropped line never reaches the odometry, which then holds its last good count."""
        return self._session.link_stats

    @property
    def link_timeout(self) -> float:
        """Seconds without a line from the board before the link counts as lost
        (default ``LINK_TIMEOUT``, 0.15 s: three feedback periods)."""
        return self._session.link_timeout

    @link_timeout.setter
    def link_timeout(self, value: float) -> None:
        if not value > 0:
            raise ValueError(f"link_timeout must be positive, not {value}")
        self._session.link_timeout = value

    @property
    def since_last_line(self) -> float:
        """Seconds since the board's last line (inf before the first)."""
        return self._session.since_last_line

    def on_link(self, callback: Callable[[LinkEvent], None]) -> None:
        """Calls ``callback`` with a ``LinkLost`` when the board goes silent for
        ``link_timeout`` s (or its device vanishes) and a ``LinkRestored`` when its
        lines flow again; from the link monitor or the reader thread, one at a time,
        in order. Keep it short: the link waits for it."""
        self._hub.on_link(callback)

    def on_reset(self, callback: Callable[[Reset], None]) -> None:
        """Calls ``callback`` with a ``Reset`` when the board's counts restart (a board
        reset, a reopened device), from the reader thread: the odometry re-baselined
        its counts and its pose carries on. ``resets`` keeps them all."""
        self._hub.on_reset(callback)

    @property
    def resets(self) -> list[Reset]:
        """Every ``Reset`` so far."""
        return list(self._hub.resets)

    def _require_link(self, what: str) -> None:
        """Raises when ``what`` cannot go out (``Session.require_link``)."""
        self._session.require_link(what)

    # ---- commands ----------------------------------------------------------------
    def set_velocity(self, linear: float, angular: float) -> None:
        """Drive at ``linear`` m/s and ``angular`` rad/s (ValueError when out of range;
        the board takes them to 3 decimals, and the limits themselves 0.001 short).
        Raises ``WcdriveConnectionError`` while the link is lost."""
        self._move(velocity_command(linear, angular))

    def set_wheels(self, left: float, right: float) -> None:
        """Wheel speeds in rad/s, forward positive (ValueError outside the WHEEL range;
        the board refuses speeds beyond its ``max_wheel`` parameter: "range" in
        ``errors``, and the command before stays in force)."""
        self._move(wheel_command(left, right))

    def stop(self) -> None:
        """Targets to zero at the normal ramp. Always sent: also while the e-stop is
        latched and while the link is lost (raises only when the port is closed or
        gone)."""
        self._session.send_motion(velocity_command(0.0, 0.0))

    def estop(self) -> None:
        """Latch the e-stop: the board stops at its emergency rate and refuses motion
        until ``reset_estop()``. Acknowledged and retried; raises when the board never
        confirms (after sending a plain stop as well). The host keeps it latched until
        ``reset_estop()``: a board that resets meanwhile (a reconnect) is latched again.
        While the link is lost the e-stop and a stop go out unconfirmed and
        ``WcdriveConnectionError`` says so."""
        session = self._session
        if session.protocol_version == 1:
            self.stop()
            raise WcdriveProtocolError(f"{session.name} speaks protocol v1 (legacy), which has no "
                                       "latched e-stop: a stop was sent instead; flash the v3 firmware")
        session.board.estop_held = True
        if not session.link_ok and not session.closed.is_set() and session.handshake.error is None:
            try:
                session.send_frame(Request.estop().command)
                self.stop()
            except WcdriveError:
                pass
            raise WcdriveConnectionError(
                f"the link to {session.name} is lost: the e-stop and a stop were sent but the "
                "board cannot confirm them. The host holds the e-stop latched (motion raises) "
                "and latches it again when the board speaks; the board's watchdog stops the chair")
        self._require_link("the e-stop")
        try:
            session.request(Request.estop())
        except (WcdriveTimeoutError, WcdriveConnectionError):
            try:
                self.stop()
            except WcdriveError:
                pass
            raise

    def reset_estop(self, timeout: float = 5.0) -> None:
        """Release the e-stop, any latched fault and a latched inhibit whose input is
        released, once the chair has parked (the board refuses earlier: this waits and
        retries until ``timeout``). The chair stays at rest until a command."""
        if self.protocol_version == 1:
            raise WcdriveProtocolError(f"{self.url} speaks protocol v1 (legacy): there is no "
                                       "e-stop to reset")
        self._require_link("reset")
        session = self._session
        # Let go of the e-stop before the reset goes out: a latch the host decided on
        # after this (a hello answered late, a restored link) would follow the reset on
        # the wire and latch the board again behind the caller's back.
        latched = self.estop_latched or bool(self.faults) or self.inhibited
        with session.estop_lock:
            held = session.board.estop_held
            session.board.estop_held = False
        deadline = time.monotonic() + timeout
        try:
            while True:
                try:
                    session.request(Request.reset())
                    session.board.estop_released()  # the last TLM predates the reset
                    if latched:     # released: the board drives after a neutral command
                        session.board.awaiting_neutral = True
                        self.wait_for_neutral(max(1.0, deadline - time.monotonic()))
                    return
                except WcdriveCommandError as exc:
                    if exc.reason != "busy" or time.monotonic() > deadline:
                        raise
                time.sleep(0.05)
        except BaseException:
            with session.estop_lock:                # not released: the host holds it again
                session.board.estop_held = session.board.estop_held or held
            raise

    @property
    def faults(self) -> tuple[str, ...]:
        """The faults the board has latched (``ENC_STALL_L``, ``DRIVER_DEAD``, ...;
        PROTOCOL.md "Faults"), as its TLM line or its ``EVT:FAULT`` lines report them;
        empty when none. Motion raises ``WcdriveFaultError`` until ``reset_estop()``."""
        return self._session.board.faults

    @property
    def reset_cause(self) -> str:
        """Why the board last reset, from its ``BOOT:`` line (``POWER_ON``, ``EXTERNAL``,
        ``BROWN_OUT``, ``WATCHDOG``, ...), or "" when no BOOT line was seen."""
        return self._session.board.reset_cause

    @property
    def estop_latched(self) -> bool:
        """True while the e-stop is latched (as the board reports it, or as sent)."""
        return self._session.board.estop_latched

    def get_param(self, name: str) -> float:
        """A runtime parameter (protocol/PROTOCOL.md, "Parameters")."""
        return self._param(Request.get(name))

    def set_param(self, name: str, value: float) -> float:
        """Sets a parameter; returns the value now in force (as the board rounded it)."""
        return self._param(Request.set(name, value))

    def save_params(self, timeout: float = 1.0) -> None:
        """Stores the parameters in force in the board's EEPROM (protocol/PROTOCOL.md,
        "Parameters in EEPROM"): it loads them at every boot from then on
        (``params_at_boot``). The board writes them in the background, one changed byte
        per 3.4 ms (up to 530 ms for the whole block; a reset before it is done leaves
        the defaults at the next boot); a save sent meanwhile is refused ``busy``, and
        this retries it until ``timeout``."""
        self._eeprom_command(Request.save(), timeout)

    def restore_defaults(self) -> None:
        """Puts every parameter back to the firmware's default. The EEPROM keeps what was
        saved (the next boot loads it again) until ``save_params()``."""
        self._eeprom_command(Request.defaults(), 0.0)

    @property
    def params_at_boot(self) -> str:
        """What the board said of its parameters when it last booted: ``PARAMS_LOADED``
        (those saved in its EEPROM) or ``PARAMS_DEFAULT,<why>`` (``blank``, ``version``,
        ``crc``, ``range``); "" when no such line was seen (a board without parameters
        in EEPROM sends none)."""
        return self._session.board.params_at_boot

    def _eeprom_command(self, request: Request, timeout: float) -> None:
        if self.protocol_version == 1:
            raise WcdriveProtocolError(f"{self.url} speaks protocol v1 (legacy): it has no "
                                       "parameters")
        self._require_link(repr(request.command.decode()))
        deadline = time.monotonic() + timeout
        while True:
            try:
                self._session.request(request)
                return
            except WcdriveCommandError as exc:
                if exc.reason != "busy" or time.monotonic() > deadline:
                    raise
            time.sleep(0.05)

    def _param(self, request: Request) -> float:
        if self.protocol_version == 1:
            raise WcdriveProtocolError(f"{self.url} speaks protocol v1 (legacy): it has no "
                                       "parameters")
        self._require_link(repr(request.command.decode()))
        data = self._session.request(request)
        if not isinstance(data, Param):
            raise WcdriveProtocolError(f"{self.url}: expected a PAR: line, got {data!r}")
        return data.value

    def send_command(self, command: bytes) -> None:
        """Any motion command (``encode_ppm(...)``, ``b"rp1.0,lp1.0,"``), framed as
        every line is: for tools; navigation code uses the methods above."""
        self._move(command)

    @property
    def recording(self) -> Recording:
        """The session so far (``connect(..., record=True)``)."""
        recording = recording_of(self._session.port)
        if recording is None:
            raise WcdriveProtocolError(f"{self.url} is not being recorded: connect(url, record=True)")
        return recording

    def _move(self, command: bytes) -> None:
        self._require_link(repr(command.decode(errors="replace")))
        faults = self.faults
        if faults:
            raise WcdriveFaultError(f"{self.url} latched a fault ({', '.join(faults)}) and "
                                    "refuses motion: find the cause, then reset_estop() once "
                                    "the chair has parked", faults)
        if self.estop_latched:
            raise WcdriveEstopError(f"the e-stop of {self.url} is latched: call reset_estop() "
                                    "once it is safe", "estop")
        refuse_unready_motion(self._session.board, command, self.url,
                              self.protocol_version == PROTOCOL_VERSION)
        self._session.send_motion(command)

    @property
    def needs_neutral(self) -> bool:
        """True while the board refuses motion until a neutral command (``wcdrive.host.neutral``):
        motion raises ``WcdriveNeutralError``."""
        return self.protocol_version == PROTOCOL_VERSION and self._session.board.awaiting_neutral

    @property
    def inhibited(self) -> bool:
        """True while an inhibit input that stops the chair is engaged (its latest TLM line):
        motion raises ``WcdriveInhibitError`` (``status.speed_capped``: one caps the speed)."""
        status = self._session.board.status
        return status is not None and status.drive_inhibited

    def wait_for_neutral(self, timeout: float = 2.0) -> None:
        """Sends stops until the board confirms neutral (``wcdrive.host.neutral``)."""
        wait_for_neutral(self._session.board, self.stop, timeout, self.url,
                         telemetry=self.protocol_version != 1)

    # ---- handshake and telemetry ------------------------------------------------------
    def wait_for_handshake(self, timeout: float = 5.0) -> int:
        """Waits until the board answered hello; returns the protocol version (4; 1 in
        legacy mode). Raises ``WcdriveProtocolError`` when it never answers (unless
        legacy) or names a version this host does not know, ``WcdriveTimeoutError``
        when the handshake is not over after ``timeout`` s."""
        return self._session.wait_for_handshake(timeout)

    @property
    def boots(self) -> int:
        """How many ``BOOT:`` lines the host has read from the board (one at start-up,
        one more for each reset): read it before causing a reset, then
        ``wait_for_boot``."""
        return self._session.boots

    def wait_for_boot(self, seen: int, timeout: float | None = 5.0) -> int:
        """Waits until the board has reset past ``seen`` boots (``boots`` before the
        reset) and answered hello again; returns the protocol version. Right after a
        reset ``wait_for_handshake`` may return at once, the host not having read the
        ``BOOT:`` line yet. ``WcdriveTimeoutError`` when no reset is seen within
        ``timeout`` s (None: no limit). It counts ``BOOT:`` lines (``Session.wait_for_boot``
        says what that misses): take ``seen`` once the handshake is done.

            seen = chair.boots
            board.dtr()                 # or a power cycle
            chair.wait_for_boot(seen, timeout=10.0)
        """
        return self._session.wait_for_boot(seen, timeout)

    def wait_for_telemetry(self, timeout: float = 5.0) -> Telemetry:
        """The next tick's telemetry (``WcdriveTimeoutError`` after ``timeout`` s)."""
        for t in self.telemetry(timeout=timeout):
            return t
        raise WcdriveTimeoutError(f"no feedback from {self.url} in {timeout} s: is the firmware "
                                  "running, at 115200 baud?")

    @overload
    def telemetry(self, timeout: float | None = None, *, link_events: Literal[False] = False
                  ) -> Iterator[Telemetry]: ...

    @overload
    def telemetry(self, timeout: float | None = None, *, link_events: Literal[True]
                  ) -> Iterator[Telemetry | LinkEvent]: ...

    def telemetry(self, timeout: float | None = None, *, link_events: bool = False
                  ) -> Iterator[Telemetry] | Iterator[Telemetry | LinkEvent]:
        """Feedback as it arrives; ends after ``timeout`` s without any, or when the
        chair is closed. ``link_events=True``: ``LinkLost`` and ``LinkRestored`` come
        too, in their place among the ticks (``isinstance`` tells them apart)."""
        if link_events:
            return self._hub.stream_with_link(self._session.closed, timeout)
        return self._hub.stream(self._session.closed, timeout)

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        """Calls ``callback`` from the reader thread with every tick."""
        self._hub.on_telemetry(callback)

    def telemetry_arrays(self) -> dict[str, np.ndarray]:
        """Everything received so far as numpy arrays."""
        return self._hub.arrays()

    @property
    def odometry(self) -> OdometryEstimate:
        """The odometry estimate now (twist timed by the board's clock)."""
        return self._hub.odometry()

    @property
    def board_clock(self) -> BoardClock:
        """The board's clock as the host tracks it: ``board_clock.filter.rate`` (host s
        per board s), ``to_host(board_time)``, ``resets``."""
        return self._hub.clock

    def odometry_stream(self, rate_hz: float = 50.0) -> Iterator[OdometryEstimate]:
        """The odometry estimate at ``rate_hz`` (50 Hz by default, as the guide's EKF
        expects), on a steady grid of times (``estimate.time``, host monotonic s): each
        estimate is extrapolated to its grid time from the latest encoder counts."""
        return self._hub.odometry_stream(self._session.closed, rate_hz)

    def on_odometry(self, callback: Callable[[OdometryEstimate], None], rate_hz: float = 50.0
                    ) -> threading.Thread:
        """Calls ``callback`` with the odometry at ``rate_hz`` from a thread of its own,
        until the chair is closed."""
        hub, closed = self._hub, self._session.closed    # the thread must not keep the chair alive

        def run() -> None:
            for estimate in hub.odometry_stream(closed, rate_hz):
                callback(estimate)

        thread = threading.Thread(target=run, name="wcdrive-odometry", daemon=True)
        thread.start()
        return thread

    # ---- the lidar ------------------------------------------------------------------------
    @property
    def has_lidar(self) -> bool:
        """Whether the chair has a lidar whose scans reach the host (``sim://`` and
        ``simavr://`` with ``lidar=``)."""
        return self._scans is not None

    @property
    def lidar(self) -> Lidar | None:
        """The chair's lidar: its model (``model.scan_hz``, ``beams``) and its mount on
        the chair (``mount``: base_link -> ``frame_id``); None without one."""
        return None if self._scans is None else self._scans.lidar

    def scan(self, timeout: float = 1.0) -> LaserScan:
        """The newest lidar scan that ``scan`` has not returned yet (a
        ``sensor_msgs/LaserScan``'s fields, ``stamp`` in host seconds as the odometry's),
        waiting up to ``timeout`` s for one. ``WcdriveError`` when the chair has no lidar,
        ``WcdriveTimeoutError`` when no scan came."""
        feed = self._lidar()
        scan = feed.wait(timeout)
        if scan is None:
            raise WcdriveTimeoutError(f"{self.url}: no lidar scan within {timeout:g} s")
        return scan

    def on_scan(self, callback: Callable[[LaserScan], None]) -> None:
        """Calls ``callback`` with every lidar scan, oldest first, from the reader thread
        (at most a tick after its turn ended). ``WcdriveError`` when the chair has no lidar."""
        self._lidar().on_scan(callback)

    def _lidar(self) -> ScanFeed:
        if self._scans is None:
            raise WcdriveError(f"{self.url}: this chair has no lidar (on sim:// or simavr://, add "
                               "?lidar=rplidar_s3, and a world=)")
        return self._scans

    # ---- lifecycle -------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        """True once the chair was closed (by ``close()`` or on the way out)."""
        return self._session.closed.is_set()

    def close(self) -> None:
        """Stops the chair, then closes the link. Safe to call twice."""
        self._finalizer()

    def __enter__(self) -> Wheelchair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
