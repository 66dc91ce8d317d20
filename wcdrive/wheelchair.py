"""``Wheelchair``: the public API over one board, as ``wcdrive.connect`` returns it.

A façade only: the protocol lives in ``wcdrive.session.Session`` (reader thread, hello,
reconnect, acknowledged requests) and telemetry with odometry in
``wcdrive.telemetry.TelemetryHub``. How the link is opened is ``wcdrive.api``'s business.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator

import numpy as np

from wcdrive.avr.avrlibc import strtod
from wcdrive.avr.f32 import f32
from wcdrive.errors import (
    WcdriveCommandError,
    WcdriveEstopError,
    WcdriveProtocolError,
    WcdriveTimeoutError,
)
from wcdrive.odometry import OdometryEstimate
from wcdrive.protocol.codec import (
    ESTOP,
    MAX_ANGULAR,
    MAX_LINEAR,
    MAX_WHEEL,
    RESET,
    ExtendedTelemetry,
    Param,
    encode_cmdvel,
    encode_get,
    encode_set,
    encode_wheel,
)
from wcdrive.session import Session
from wcdrive.telemetry import Telemetry, TelemetryHub
from wcdrive.transports.port import Port
from wcdrive.transports.recording import Recording

__all__ = ["Telemetry", "Wheelchair"]


def _as_board_reads(value: float, limit: float) -> float:
    """``value`` (already checked against ``limit``) at the 3 decimals the codec writes,
    stepped 0.001 toward zero when the board would read that text just past its
    binary32 limit: avr-libc's ``strtod`` is not correctly rounded, and reads "9.400"
    as 9.4000006, above the firmware's 9.3999996, so ``x:0.000,t:9.400,`` is refused."""
    text = f"{abs(value):.3f}"
    while strtod(text.encode())[0] > f32(limit):
        text = f"{float(text) - 0.001:.3f}"
    return math.copysign(float(text), value)


class Wheelchair:
    """A chair behind a serial-like ``port`` (a ``wcdrive.transports.port.Port``).
    ``reopen``: how to open the same device again after it vanished (device paths),
    tried for ``reconnect_timeout`` s. ``on_close`` runs after the port is closed."""

    def __init__(self, port: Port, *, odometry_method: str = "position",
                 on_close: Callable[[], None] | None = None,
                 reopen: Callable[[], Port] | None = None, reconnect_timeout: float = 60.0,
                 ) -> None:
        self._on_close = on_close
        self._hub = TelemetryHub(odometry_method)
        self._session = Session(port, self._hub.deliver, reopen=reopen,
                                reconnect_timeout=reconnect_timeout)

    # ---- what the session knows ------------------------------------------------------
    @property
    def protocol_version(self) -> int:
        """The protocol version the board answered hello with (1 until a v2 board does)."""
        return self._session.protocol_version

    @property
    def firmware(self) -> str:
        """The firmware's name and version from its hello answer ("" before)."""
        return self._session.firmware

    @property
    def status(self) -> ExtendedTelemetry | None:
        """The latest ``TLM:`` line (v2 boards), or None."""
        return self._session.status

    @property
    def errors(self) -> list[str]:
        """Every ``ERR:`` reason the board sent, and "link lost"."""
        return self._session.errors

    @property
    def events(self) -> list[str]:
        """Every ``EVT:`` the board sent, and LINK_LOST / RECONNECTED."""
        return self._session.events

    @property
    def reconnect_timeout(self) -> float:
        """Seconds a vanished device is reopened for."""
        return self._session.reconnect_timeout

    @reconnect_timeout.setter
    def reconnect_timeout(self, value: float) -> None:
        self._session.reconnect_timeout = value

    # ---- commands ----------------------------------------------------------------
    def set_velocity(self, linear: float, angular: float) -> None:
        """Drive at ``linear`` m/s and ``angular`` rad/s (ValueError when out of range;
        the board takes them to 3 decimals, and the limits themselves 0.001 short)."""
        encode_cmdvel(linear, angular)          # ValueError when out of range
        self._move(encode_cmdvel(_as_board_reads(linear, MAX_LINEAR),
                                 _as_board_reads(angular, MAX_ANGULAR)))

    def set_wheels(self, left: float, right: float) -> None:
        """Wheel speeds in rad/s, forward positive (ValueError outside the WHEEL range;
        the board refuses speeds beyond its ``max_wheel`` parameter: ``ERR:range`` in
        ``errors``, and the command before stays in force)."""
        encode_wheel(right, left)               # ValueError when out of range
        self._move(encode_wheel(_as_board_reads(right, MAX_WHEEL), _as_board_reads(left, MAX_WHEEL)))

    def stop(self) -> None:
        """Targets to zero at the normal ramp (also while the e-stop is latched)."""
        self._session.send(self._session.motion_line(encode_cmdvel(0.0, 0.0)))

    def estop(self) -> None:
        """Latch the e-stop: the board stops at its emergency rate and refuses motion
        until ``reset_estop()``. Acknowledged and retried; raises when the board never
        confirms (after sending a plain stop as well). The host keeps it latched until
        ``reset_estop()``: a board that resets meanwhile (a reconnect) is latched again."""
        if self.protocol_version < 2:
            self.stop()
            raise WcdriveProtocolError("this board speaks protocol v1, which has no latched "
                                       "e-stop: a stop was sent instead; flash the v2 firmware")
        self._session.estop_held = True
        try:
            self._session.request(ESTOP.rstrip(b"\n"))
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
                self._session.request(RESET.rstrip(b"\n"))
                self._session.estop_held = False
                self._session.estop_announced = False
                self._session.status = None          # the last TLM predates the reset
                return
            except WcdriveCommandError as exc:
                if exc.reason != "busy" or time.monotonic() > deadline:
                    raise
            time.sleep(0.05)

    @property
    def estop_latched(self) -> bool:
        """True while the e-stop is latched (as the board reports it, or as sent)."""
        status = self._session.status
        if status is not None and status.estop_latched:
            return True
        return self._session.estop_held or self._session.estop_announced

    def get_param(self, name: str) -> float:
        """A runtime parameter (protocol/PROTOCOL.md, "Parameters")."""
        return self._param(encode_get(name))

    def set_param(self, name: str, value: float) -> float:
        """Sets a parameter; returns the value now in force (as the board rounded it)."""
        return self._param(encode_set(name, value))

    def _param(self, command: bytes) -> float:
        if self.protocol_version < 2:
            raise WcdriveProtocolError("parameters need a protocol-v2 board")
        data = self._session.request(command)
        if not isinstance(data, Param):
            raise WcdriveProtocolError(f"expected a PAR: line, got {data!r}")
        return data.value

    def send_command(self, command: bytes) -> None:
        """Any protocol command (``encode_ppm(...)``, ``b"rp1.0,lp1.0,"``), framed with a
        checksum on a v2 board: for tools; navigation code uses the methods above."""
        self._move(command)

    @property
    def recording(self) -> Recording:
        """The session so far (``connect(..., record=True)``)."""
        recording = getattr(self._session.port, "recording", None)
        if not isinstance(recording, Recording):
            raise WcdriveProtocolError("not recording: connect(url, record=True)")
        return recording

    def _move(self, command: bytes) -> None:
        if self.estop_latched:
            raise WcdriveEstopError("the e-stop is latched: call reset_estop() once it is safe",
                                    "estop")
        self._session.send(self._session.motion_line(command))

    # ---- handshake and telemetry ------------------------------------------------------
    def wait_for_handshake(self, timeout: float = 5.0) -> int:
        """Waits until the board answered hello (v2) or three hellos went unanswered
        (v1); returns the protocol version."""
        return self._session.wait_for_handshake(timeout)

    def wait_for_telemetry(self, timeout: float = 5.0) -> Telemetry:
        """The next tick's telemetry (``WcdriveTimeoutError`` after ``timeout`` s)."""
        for t in self.telemetry(timeout=timeout):
            return t
        raise WcdriveTimeoutError(f"no feedback from the board in {timeout} s: is the firmware running?")

    def telemetry(self, timeout: float | None = None) -> Iterator[Telemetry]:
        """Feedback as it arrives; ends after ``timeout`` s without any."""
        return self._hub.stream(self._session.closed, timeout)

    def on_telemetry(self, callback: Callable[[Telemetry], None]) -> None:
        """Calls ``callback`` from the reader thread with every tick."""
        self._hub.on_telemetry(callback)

    def telemetry_arrays(self) -> dict[str, np.ndarray]:
        """Everything received so far as numpy arrays."""
        return self._hub.arrays()

    @property
    def odometry(self) -> OdometryEstimate:
        """The odometry estimate now."""
        return self._hub.odometry()

    def odometry_stream(self, rate_hz: float = 50.0) -> Iterator[OdometryEstimate]:
        """The odometry estimate at ``rate_hz`` (50 Hz by default, as the guide's EKF
        expects), on a steady grid of times (``estimate.time``, host monotonic s): each
        estimate is extrapolated to its grid time from the latest encoder counts."""
        return self._hub.odometry_stream(self._session.closed, rate_hz)

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

    # ---- lifecycle -------------------------------------------------------------------
    def close(self) -> None:
        """Stops the chair, then closes the link. Safe to call twice."""
        if self._session.closed.is_set():
            return
        try:
            self._session.close(self._session.motion_line(encode_cmdvel(0.0, 0.0)))
        finally:
            if self._on_close:
                self._on_close()

    def __enter__(self) -> Wheelchair:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
