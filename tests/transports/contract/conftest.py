"""The backends of the contract suite and the helpers its tests share.

Every test in ``tests/transports/contract/`` takes the ``backend`` fixture and so runs once per
``Port`` backend (the pyserial / python-can pattern: one suite, many backends):

- ``wcsim``: ``serial_for_url("wcsim://")``, the bit-exact port of the firmware and
  the plant in process;
- ``wcavr``: ``serial_for_url("wcavr://<elf>")``, the compiled firmware in simavr
  (marked ``simavr``);
- ``pty``: a ``PtyBridge`` over a ``SimulatedBoard``, opened by path with a real
  ``serial.Serial`` (the code path of /dev/ttyACM0);
- ``wccan``: ``serial_for_url("wccan://virtual/<channel>")``, the host end of CAN,
  with a ``CanGateway`` serving a ``wcsim://`` chair on the same virtual bus;
- ``recording``: ``RecordingPort`` around ``wcsim://``.

A ``Backend`` opens ports on the same URL or path as often as a test wants and closes
all of them, and what it started (bridge, gateway), when the test ends; it then fails
the test if a thread started during it is still alive.
"""

from __future__ import annotations

import contextlib
import itertools
import re
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest
import serial

from wcdrive.transports.port import Port

#: Simulated time against the wall clock of the simulated chairs (wcsim, pty, CAN):
#: feedback every 12.5 ms, so the suite runs quickly, yet a 100 kB read takes
#: about 25 s to fill.
SPEED = 4

#: A line of the board, complete and well-formed (protocol/PROTOCOL.md).
_VEL = rb"(?:-?\d+\.\d\d|nan|inf|ovf)"
LINE = re.compile(
    rb"(?:BOOT:final_control(?:,[A-Z_]+)?|HELLO:3,final_control,[\w.]+,[0-9a-f]{8}"
    rb"|ENC:-?\d+,-?\d+,VEL:" + _VEL + rb"," + _VEL + rb",MODE:(?:WHEEL|CMDVEL|PPM)"
    rb"|TLM:\d+(?:,\d+){12,15}|ACK:\d+|NAK:\d+,[a-z]+|ERR:[a-z]+|EVT:[A-Z_]+(?:,[A-Za-z_]+)?"
    rb"|PAR:[a-z_]+,\d+(?:\.\d+)?)\r\n")
FEEDBACK = re.compile(rb"ENC:(-?\d+),(-?\d+),VEL:[^,]+,[^,]+,MODE:(WHEEL|CMDVEL|PPM)\r\n")
BOOT = b"BOOT:final_control,POWER_ON\r\n"

_channels = itertools.count()


@dataclass
class Backend:
    """One backend: ``open()`` gives a new port on the same URL or path."""

    name: str
    opener: Callable[[float | None], Port]
    #: The board resets when the port opens, so its BOOT line is the first it reads
    #: (as a Mega on USB does through DTR). Not so on a pty (the bridge's board runs
    #: on, and pyserial flushes the input at open) nor over CAN (the gateway's chair
    #: runs on).
    boots_on_open: bool = True
    #: ``write`` takes any bytes, a line split across writes included. Not so the CAN
    #: host end: each write must hold complete protocol lines that have a CAN form.
    byte_stream_writes: bool = True
    #: What a ``read`` blocked in another thread may raise when the port is closed
    #: (besides returning). Ours return what they have; pyserial's posix port goes
    #: on with its closed descriptor (``TypeError`` for ``None``) or reports the fd.
    close_wakes_with: tuple[type[BaseException], ...] = ()
    #: What ``in_waiting`` raises on a closed port: ``PortNotOpenError``, but
    #: pyserial's posix port calls ``ioctl(None)``, a ``TypeError``.
    in_waiting_closed_raises: tuple[type[BaseException], ...] = (serial.SerialException,)
    ports: list[Port] = field(default_factory=list)
    cleanups: list[Callable[[], Any]] = field(default_factory=list)

    def open(self, timeout: float | None = 0.5) -> Port:
        port = self.opener(timeout)
        self.ports.append(port)
        return port

    def close_all(self) -> None:
        """Closes every port opened, then what the backend started (last first), even
        when one of them raises."""
        with contextlib.ExitStack() as stack:
            for cleanup in self.cleanups:
                stack.callback(cleanup)
            for port in self.ports:
                stack.callback(port.close)


def _wcsim(timeout: float | None) -> serial.SerialBase:
    return serial.serial_for_url(f"wcsim://?speed={SPEED}", timeout=timeout)


def _make(name: str, request: pytest.FixtureRequest) -> Backend:
    if name == "wcsim":
        return Backend(name, _wcsim)
    if name == "wcavr":
        elf = request.getfixturevalue("elf")
        return Backend(name, lambda timeout: serial.serial_for_url(f"wcavr://{elf}?realtime=0",
                                                                   timeout=timeout))
    if name == "pty":
        from wcdrive.boards.sim_board import SimulatedBoard
        from wcdrive.transports.pty_bridge import PtyBridge

        bridge = PtyBridge(SimulatedBoard(speed=SPEED).start()).start()
        backend = Backend(name, lambda timeout: serial.Serial(bridge.path, 115200, timeout=timeout),
                          boots_on_open=False,
                          close_wakes_with=(serial.SerialException, OSError, TypeError),
                          in_waiting_closed_raises=(serial.SerialException, OSError, TypeError))
        backend.cleanups.append(bridge.close)
        return backend
    if name == "wccan":
        import can

        from wcdrive.transports.can_link import CanGateway

        channel = f"wc-contract-{next(_channels)}"
        chair = _wcsim(0.1)
        gateway = CanGateway(can.Bus(interface="virtual", channel=channel), chair).start()
        backend = Backend(
            name, lambda timeout: serial.serial_for_url(f"wccan://virtual/{channel}", timeout=timeout),
            boots_on_open=False, byte_stream_writes=False)
        backend.cleanups += [chair.close, gateway.close]     # run in reverse: gateway first
        return backend
    if name == "recording":
        from wcdrive.transports.recording import RecordingPort

        return Backend(name, lambda timeout: RecordingPort(_wcsim(timeout)))
    raise ValueError(name)


BACKENDS = [
    pytest.param("wcsim", id="wcsim"),
    pytest.param("wcavr", id="wcavr", marks=pytest.mark.simavr),
    pytest.param("pty", id="pty"),
    pytest.param("wccan", id="wccan"),
    pytest.param("recording", id="recording"),
]


@pytest.fixture(params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> Iterator[Backend]:
    before = set(threading.enumerate())
    made = _make(request.param, request)
    try:
        yield made
    finally:
        made.close_all()
        assert_no_new_threads(before)


def assert_no_new_threads(before: set[threading.Thread], grace: float = 5.0) -> None:
    """Threads started since ``before`` must end within ``grace`` s of the cleanup."""
    deadline = time.monotonic() + grace
    while True:
        left = [t for t in threading.enumerate() if t not in before and t.is_alive()]
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.02)
    assert not left, f"threads left running: {[t.name for t in left]}"


# ---- helpers -----------------------------------------------------------------------


def call_within(seconds: float, fn: Callable[[], Any]) -> tuple[Any, float]:
    """Runs ``fn`` in a thread; returns its result and how long it took, or fails the
    test when it is still running after ``seconds`` (a read that ignores its timeout
    fails the test instead of hanging the suite: the fixture's close wakes it)."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:   # handed to the test's thread
            box["error"] = exc

    thread = threading.Thread(target=run, name="contract-call", daemon=True)
    t0 = time.monotonic()
    thread.start()
    thread.join(seconds)
    elapsed = time.monotonic() - t0
    if thread.is_alive():
        pytest.fail(f"still blocked after {seconds:.1f} s")
    if "error" in box:
        raise box["error"]
    return box["value"], elapsed


def split_lines(data: bytes) -> tuple[list[bytes], bytes]:
    """The complete ``\\n``-terminated lines of ``data`` and the incomplete rest."""
    *lines, rest = data.split(b"\n")
    return [line + b"\n" for line in lines], rest


def assert_well_formed(lines: list[bytes]) -> None:
    bad = [line for line in lines if not LINE.fullmatch(line)]
    assert not bad, f"malformed lines: {bad[:5]}"


def feedback(lines: list[bytes]) -> list[re.Match[bytes]]:
    return [m for m in map(FEEDBACK.fullmatch, lines) if m]


def read_until(port: Port, done: Callable[[bytes], bool], seconds: float = 15.0,
               chunk: Callable[[Port], int] = lambda port: max(1, port.in_waiting)) -> bytes:
    """Reads (``chunk`` bytes at a time, within the port's timeout) until ``done`` of
    all bytes so far, or fails after ``seconds``."""
    data = bytearray()
    deadline = time.monotonic() + seconds
    while not done(bytes(data)):
        if time.monotonic() > deadline:
            pytest.fail(f"gave up after {seconds} s; got {bytes(data[-300:])!r}")
        data += port.read(chunk(port))
    return bytes(data)


def n_feedback(n: int, after: bytes = b"") -> Callable[[bytes], bool]:
    """``done`` for ``read_until``: ``n`` complete feedback lines after ``after``."""
    def done(data: bytes) -> bool:
        at = data.find(after) if after else 0
        return at >= 0 and len(feedback(split_lines(data[at:])[0])) >= n
    return done


def wait_alive(backend: Backend, port: Port) -> bytes:
    """The first bytes of a freshly opened port: its BOOT line first where the board
    boots on open, then feedback lines, all well-formed."""
    data = read_until(port, n_feedback(2))
    lines, _ = split_lines(data)
    if backend.boots_on_open:
        assert data.startswith(BOOT), data[:100]
    else:
        lines = lines[1:]            # may begin in the middle of a line
    assert_well_formed(lines)
    return data
