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
- ``recording``: ``RecordingPort`` around ``wcsim://``;
- ``faulty``: ``FaultyPort`` around ``wcsim://`` with no fault, judging the board's
  bytes by the line (``lines=True``: the path its faults take);
- ``wceddie``: ``serial_for_url("wceddie://")``, the simulated Eddie board, which
  speaks another protocol (``EDDIE``: it answers commands and sends nothing unasked);
- ``device``: a real board, ``serial.Serial(<path>)``, only with ``--device <path>``
  (``pytest tests/transports/contract --device /dev/ttyACM0``); not collected without.

A backend's ``Dialect`` says what its board speaks: how a line ends and looks, a
request it answers, and whether it sends feedback unasked. The tests that need the
final_control firmware's feedback stream (moving wheels, its RX ring) are marked
``final_control`` and run on its backends only.

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

from wcdrive.protocol.codec import HELLO
from wcdrive.transports.port import Port

#: Simulated time against the wall clock of the simulated chairs (wcsim, pty, CAN):
#: feedback every 12.5 ms, so the suite runs quickly, yet a 100 kB read takes
#: about 25 s to fill.
SPEED = 4

#: A line of the board, complete and well-formed (protocol/PROTOCOL.md).
_VEL = rb"(?:-?\d+\.\d\d|nan|inf|ovf)"
LINE = re.compile(
    rb"(?:BOOT:final_control(?:,[A-Z_]+)?|HELLO:3,final_control,[\w.]+,[0-9a-f]{8}(?:,\d)?"
    rb"|ENC:-?\d+,-?\d+,VEL:" + _VEL + rb"," + _VEL + rb",MODE:(?:WHEEL|CMDVEL|PPM)"
    rb"|TLM:\d+(?:,\d+){12,15}|ACK:\d+|NAK:\d+,[a-z]+|ERR:[a-z]+|EVT:[A-Z_]+(?:,[A-Za-z_]+)?"
    rb"|PAR:[a-z_]+,\d+(?:\.\d+)?)\r\n")
FEEDBACK = re.compile(rb"ENC:(-?\d+),(-?\d+),VEL:[^,]+,[^,]+,MODE:(WHEEL|CMDVEL|PPM)\r\n")
BOOT = b"BOOT:final_control,POWER_ON\r\n"

_channels = itertools.count()


@dataclass(frozen=True)
class Dialect:
    """What a backend's board speaks: lines end in ``eol`` and match ``line``;
    ``request`` is a command it answers with ``answer``; ``streams``: it sends feedback
    unasked (else it speaks only when asked)."""

    name: str
    eol: bytes
    line: re.Pattern[bytes]
    request: bytes
    answer: re.Pattern[bytes]
    streams: bool


FINAL_CONTROL = Dialect("final_control", b"\n", LINE, HELLO, re.compile(rb"HELLO:3,final_control,"), True)
#: The Eddie's firmware: hex words, CR-terminated; HWVER answers the hardware version.
EDDIE = Dialect("eddie", b"\r", re.compile(rb"(?:[0-9A-F]{3,8}(?: [0-9A-F]{3,8})*|ERROR(?: \w+)?)?\r"),
                b"HWVER\r", re.compile(rb"0001\r"), False)


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
    #: The BOOT line it opens with: the simulated boards' power-on; a real board reset by
    #: DTR names its own cause (EXTERNAL, or NONE behind a bootloader that clears MCUSR).
    boot: re.Pattern[bytes] = re.compile(re.escape(BOOT))
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
    dialect: Dialect = FINAL_CONTROL
    ports: list[Port] = field(default_factory=list)
    cleanups: list[Callable[[], Any]] = field(default_factory=list)

    def open(self, timeout: float | None = 0.5) -> Port:
        port = self.opener(timeout)
        self.ports.append(port)
        return port

    def ask(self, port: Port, n: int = 1) -> None:
        """Makes a board that speaks only when asked say something (``n`` answers);
        nothing for one that streams."""
        if not self.dialect.streams:
            port.write(self.dialect.request * n)

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
    if name == "faulty":
        from wcdrive.transports.faulty import FaultyPort

        return Backend(name, lambda timeout: FaultyPort(_wcsim(timeout), lines=True))
    if name == "wceddie":
        return Backend(name, lambda timeout: serial.serial_for_url(f"wceddie://?speed={SPEED}",
                                                                   timeout=timeout),
                       dialect=EDDIE, boots_on_open=False)             # it has no BOOT line
    if name == "device":
        path = request.config.getoption("--device")
        return Backend(name, lambda timeout: serial.Serial(path, 115200, timeout=timeout),
                       boot=re.compile(rb"BOOT:final_control,[A-Z_]+\r\n"),
                       close_wakes_with=(serial.SerialException, OSError, TypeError),
                       in_waiting_closed_raises=(serial.SerialException, OSError, TypeError))
    raise ValueError(name)


BACKENDS = [
    pytest.param("wcsim", id="wcsim"),
    pytest.param("wcavr", id="wcavr", marks=pytest.mark.simavr),
    pytest.param("pty", id="pty"),
    pytest.param("wccan", id="wccan"),
    pytest.param("recording", id="recording"),
    pytest.param("faulty", id="faulty"),
    pytest.param("wceddie", id="wceddie"),
]
#: The backends whose board is not final_control's.
OTHER_DIALECTS = {"wceddie"}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "final_control: needs the final_control firmware's feedback "
                                       "stream; runs on its backends only")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """``backend``: every backend (and ``device`` with ``--device``); for a test marked
    ``final_control``, those whose board is final_control's."""
    if "backend" not in metafunc.fixturenames:
        return
    params = list(BACKENDS)
    if metafunc.config.getoption("--device", None):
        params.append(pytest.param("device", id="device"))
    if metafunc.definition.get_closest_marker("final_control") is not None:
        params = [p for p in params if p.id not in OTHER_DIALECTS]
    metafunc.parametrize("backend", params, indirect=True)


@pytest.fixture
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


def split_lines(data: bytes, eol: bytes = b"\n") -> tuple[list[bytes], bytes]:
    """The complete lines of ``data`` (each ending in ``eol``) and the incomplete rest."""
    *lines, rest = data.split(eol)
    return [line + eol for line in lines], rest


def assert_well_formed(lines: list[bytes], dialect: Dialect = FINAL_CONTROL) -> None:
    bad = [line for line in lines if not dialect.line.fullmatch(line)]
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


def n_talked(backend: Backend, n: int) -> Callable[[bytes], bool]:
    """``done`` for ``read_until``: ``n`` feedback lines, or ``n`` answers from a board
    that speaks only when asked."""
    if backend.dialect.streams:
        return n_feedback(n)
    return lambda data: len(backend.dialect.answer.findall(data)) >= n


def wait_alive(backend: Backend, port: Port) -> bytes:
    """The first bytes of a freshly opened port: its BOOT line first where the board
    boots on open, then feedback lines, all well-formed. A board that speaks only when
    asked: the answers to two requests."""
    if not backend.dialect.streams:
        backend.ask(port, 2)
        data = read_until(port, n_talked(backend, 2))
        assert_well_formed(split_lines(data, backend.dialect.eol)[0], backend.dialect)
        return data
    data = read_until(port, n_feedback(2))
    lines, _ = split_lines(data)
    if backend.boots_on_open:
        assert backend.boot.match(data), data[:100]
    else:
        lines = lines[1:]            # may begin in the middle of a line
    assert_well_formed(lines)
    return data
