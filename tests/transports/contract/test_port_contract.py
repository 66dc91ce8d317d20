"""The byte-level contract of a ``Port`` (``wcdrive.transports.port``), one suite run
against every backend (``conftest.py``: wcsim, wcavr, pty, wccan, recording, faulty,
wceddie, and a real board with ``--device``).

What a session relies on: opening and closing (twice is fine; a closed port raises
``serial.SerialException``), ``read`` honouring ``timeout`` (0 never blocks, ``None``
waits for all), bytes read one at a time forming the same well-formed lines as bulk
reads, ``in_waiting`` bytes readable at once, writes far larger than the firmware's
64-byte RX ring, ``close`` waking a ``read`` blocked in another thread, and opening the
same URL or path again.
"""

from __future__ import annotations

import threading
import time

import pytest
import serial

from tests.transports.contract.conftest import (
    SPEED,
    Backend,
    assert_no_new_threads,
    assert_well_formed,
    call_within,
    feedback,
    n_feedback,
    n_talked,
    read_until,
    split_lines,
    wait_alive,
)
from wcdrive.protocol.codec import HELLO, encode_cmdvel, encode_wheel, frame
from wcdrive.transports.port import Port

#: Slack on top of a timeout for a loaded two-core machine.
SLACK = 1.5


def test_every_backend_is_a_port(backend: Backend) -> None:
    port = backend.open()
    assert isinstance(port, Port)
    wait_alive(backend, port)


def test_open_use_close(backend: Backend) -> None:
    port = backend.open(timeout=0.2)
    assert port.is_open
    wait_alive(backend, port)
    request, answer = backend.dialect.request, backend.dialect.answer
    assert port.write(request) == len(request)
    port.flush()
    read_until(port, lambda data: answer.search(data) is not None)

    call_within(5.0, port.close)
    assert not port.is_open
    port.close()                                       # closing twice is fine
    for use in (lambda: port.read(1), lambda: port.write(HELLO), port.flush):
        with pytest.raises(serial.SerialException):
            use()
    with pytest.raises(backend.in_waiting_closed_raises):
        port.in_waiting   # noqa: B018


def test_read_returns_at_its_timeout_with_fewer_bytes(backend: Backend) -> None:
    port = backend.open(timeout=0.2)
    wait_alive(backend, port)
    for _ in range(2):
        backend.ask(port)
        data, took = call_within(0.2 + SLACK, lambda: port.read(100_000))
        assert took >= 0.19, f"returned after {took:.3f} s, before its timeout"
        assert 0 < len(data) < 100_000


def test_timeout_zero_never_blocks(backend: Backend) -> None:
    port = backend.open(timeout=0)
    backend.ask(port, 3)
    got = bytearray()
    deadline = time.monotonic() + 15
    while not n_talked(backend, 3)(bytes(got)):               # poll, as a non-blocking host does
        assert time.monotonic() < deadline, bytes(got)
        data, took = call_within(SLACK, lambda: port.read(100_000))
        assert took < 0.5, f"a timeout=0 read took {took:.3f} s"
        got += data
        time.sleep(0.01)
    if backend.boots_on_open:
        assert backend.boot.match(bytes(got)), bytes(got[:100])


def test_timeout_none_waits_for_every_byte(backend: Backend) -> None:
    port = backend.open(timeout=None)
    backend.ask(port, 120)                                     # 565 bytes of answers at least
    for size in (1, 64, 500):
        data, _ = call_within(15.0, lambda size=size: port.read(size))
        assert len(data) == size


def test_timeout_set_on_an_open_port_takes_effect(backend: Backend) -> None:
    port = backend.open(timeout=None)
    wait_alive(backend, port)
    port.timeout = 0.2
    assert port.timeout == 0.2
    data, took = call_within(0.2 + SLACK, lambda: port.read(100_000))
    assert took >= 0.19 and len(data) < 100_000


def test_byte_reads_give_the_lines_of_bulk_reads(backend: Backend) -> None:
    """Two ports on the same board from its boot: the idle board's lines are the same
    whether read one byte at a time or 4 kB at a time."""
    first = backend.open(timeout=0.5)
    backend.ask(first, 8)
    bytewise = read_until(first, n_talked(backend, 8), chunk=lambda port: 1)
    first.close()
    second = backend.open(timeout=0.5)
    backend.ask(second, 8)
    bulk = read_until(second, n_talked(backend, 8), chunk=lambda port: 4096)
    eol = backend.dialect.eol
    a, b = split_lines(bytewise, eol)[0], split_lines(bulk, eol)[0]
    if not backend.boots_on_open and backend.dialect.streams:
        a, b = a[1:], b[1:]                  # the stream was joined mid-way
        # and the boot's lines (BOOT, EVT:PARAMS_*) only the first reader may have seen
        a = [line for line in a if not line.startswith((b"BOOT:", b"EVT:PARAMS"))]
        b = [line for line in b if not line.startswith((b"BOOT:", b"EVT:PARAMS"))]
    assert_well_formed(a, backend.dialect)
    assert_well_formed(b, backend.dialect)
    k = min(len(a), len(b))
    assert k >= 7
    assert a[:k] == b[:k]


def _neutral(port: Port) -> None:
    """A neutral command (one with a CAN form), standing for 3 of the board's ticks: a
    board just out of reset drives only after one (docs/safety.md, "Neutral before
    motion")."""
    port.write(encode_cmdvel(0.0, 0.0) + b"\n")
    read_until(port, n_feedback(4))


def _drive_and_read(port: Port, chunk: int, wheel_lines: int, neutral: bool = False) -> list[bytes]:
    """Drives both wheels forward (the command resent well within the watchdog) and
    reads ``chunk`` bytes at a time until ``wheel_lines`` feedback lines say WHEEL.
    ``neutral``: first a neutral command, which a board just out of reset needs before it
    drives (docs/safety.md, "Neutral before motion"), standing for 3 of the board's
    ticks (3 feedback lines)."""
    command = encode_wheel(2.0, 2.0) + b"\n"
    data = bytearray()
    if neutral:
        port.write(encode_wheel(0.0, 0.0) + b"\n")
        deadline = time.monotonic() + 30
        while data.count(b"ENC:") < 4:
            assert time.monotonic() < deadline, bytes(data[-300:])
            data += port.read(chunk)
    next_command = 0.0
    deadline = time.monotonic() + 30
    while True:
        now = time.monotonic()
        assert now < deadline, bytes(data[-300:])
        if now >= next_command:
            port.write(command)
            next_command = now + 0.1 / SPEED
        data += port.read(chunk)
        lines, _ = split_lines(bytes(data))
        if sum(m[3] == b"WHEEL" for m in feedback(lines)) >= wheel_lines:
            return lines


@pytest.mark.final_control
def test_byte_reads_of_a_moving_chair(backend: Backend) -> None:
    """While the chair drives, 1-byte reads and then bulk reads on one port give
    whole, well-formed lines whose encoder counts run on without a gap in between:
    the right one counts up, the left one down (it is mirrored)."""
    port = backend.open(timeout=0.05)
    wait_alive(backend, port)
    bytewise = _drive_and_read(port, 1, 20, neutral=True)
    bulk = _drive_and_read(port, 4096, 20)
    for lines in (bytewise, bulk):
        assert_well_formed(lines[1:])
    counts = [(int(m[1]), int(m[2])) for m in feedback(bytewise[1:] + bulk[1:]) if m[3] == b"WHEEL"]
    lefts, rights = zip(*counts, strict=True)
    assert list(rights) == sorted(rights) and rights[-1] > rights[0] + 100
    assert list(lefts) == sorted(lefts, reverse=True) and lefts[-1] < lefts[0] - 100


def test_in_waiting_bytes_are_read_without_waiting(backend: Backend) -> None:
    port = backend.open(timeout=5.0)
    wait_alive(backend, port)
    for _ in range(3):
        backend.ask(port, 25)                                  # 125 bytes of answers
        deadline = time.monotonic() + 15
        while port.in_waiting < 100:
            assert time.monotonic() < deadline, "in_waiting stays below 100"
            time.sleep(0.01)
        n = port.in_waiting
        data, took = call_within(5.0, lambda n=n: port.read(n))
        assert len(data) == n
        assert took < 0.5, f"reading {n} waiting bytes took {took:.3f} s (timeout 5 s)"


@pytest.mark.final_control
def test_a_write_larger_than_the_rx_ring(backend: Backend) -> None:
    """1.7 kB in one write (the firmware's RX ring holds 64 bytes, the wire drains
    11.5 bytes a millisecond): the write returns its length at once, the board takes
    every line (no ERR: a lost byte would break a line), keeps sending feedback, and
    the last command (WHEEL, with sequence number 4242) is the one in force.

    The burst is whole lines that have a CAN form (CMDVEL, then a framed WHEEL), as
    the wccan backend requires of every write (CanLink.write turns each line into
    frames); to the other backends it is an ordinary byte burst. Over CAN the gateway
    makes each unsequenced CMDVEL a v3 frame with sequence number 0, which the board
    acknowledges: with at most 3 answers a tick, ACK:4242 is among those left out, so
    there the check is the mode that follows (a known cost of unsequenced CAN commands)."""
    port = backend.open(timeout=0.1)
    wait_alive(backend, port)
    _neutral(port)
    burst = (encode_cmdvel(0.1, 0.0) + b"\n") * 100 + frame(encode_wheel(1.0, 1.0), 4242)
    assert len(burst) > 1500
    written, _ = call_within(5.0, lambda: port.write(burst))
    assert written == len(burst)
    marker = b"ACK:4242\r\n" if backend.byte_stream_writes else b"MODE:WHEEL\r\n"
    data = read_until(port, n_feedback(3, after=marker), seconds=30)
    lines = split_lines(data)[0][1:]
    assert_well_formed(lines)
    assert not [line for line in lines if line.startswith((b"ERR:", b"NAK:"))]
    after = feedback(lines[next(i for i, line in enumerate(lines) if marker in line):])
    assert [m[3] for m in after] == [b"WHEEL"] * len(after)


def test_lines_split_and_joined_across_writes(backend: Backend) -> None:
    """Three framed lines in one write are three commands. A line written a byte at a
    time is one command on a byte stream; the CAN host end takes whole lines only
    (a part of one has no CAN form) and refuses the part with ValueError. A board of
    another dialect: three of its requests in one write, then one a byte at a time."""
    port = backend.open(timeout=0.1)
    wait_alive(backend, port)
    if not backend.dialect.streams:
        request = backend.dialect.request
        port.write(request * 3)
        read_until(port, n_talked(backend, 3))
        for i in range(len(request)):
            assert port.write(request[i:i + 1]) == 1
        read_until(port, n_talked(backend, 1))
        return
    _neutral(port)
    port.write(b"".join(frame(encode_wheel(0.5, 0.5), seq) for seq in (11, 12, 13)))
    # and a tick after them: the board answers at most 3 commands a tick
    data = read_until(port, n_feedback(1, after=b"ACK:13\r\n"))
    assert data.index(b"ACK:11\r\n") < data.index(b"ACK:12\r\n") < data.index(b"ACK:13\r\n")
    line = frame(encode_wheel(0.7, 0.7), 14)
    if not backend.byte_stream_writes:
        with pytest.raises(ValueError):
            port.write(line[:5])
        port.write(line)
    else:
        for i in range(len(line)):
            assert port.write(line[i:i + 1]) == 1
    read_until(port, lambda data: b"ACK:14\r\n" in data)


@pytest.mark.parametrize("timeout", [None, 60.0], ids=["timeout=None", "timeout=60"])
def test_close_wakes_a_blocked_read(backend: Backend, timeout: float | None) -> None:
    """A thread blocked in ``read(100_000)`` (about 25 s of feedback away) returns
    what it has, or raises, within 3 s of another thread closing the port."""
    port = backend.open(timeout=timeout)
    wait_alive(backend, port)
    box: dict[str, object] = {}

    def reader() -> None:
        try:
            box["data"] = port.read(100_000)
        except BaseException as exc:
            box["error"] = exc

    thread = threading.Thread(target=reader, name="blocked-reader", daemon=True)
    thread.start()
    time.sleep(0.3)
    assert thread.is_alive(), f"the read returned before the close: {box}"
    t0 = time.monotonic()
    port.close()
    thread.join(3.0)
    assert not thread.is_alive(), "the read is still blocked 3 s after close()"
    assert time.monotonic() - t0 < 3.0
    if "error" in box:
        assert isinstance(box["error"], backend.close_wakes_with), box["error"]
    else:
        assert isinstance(box["data"], bytes) and len(box["data"]) < 100_000
    with pytest.raises(serial.SerialException):
        port.read(1)


def test_reopen(backend: Backend) -> None:
    """After close the same URL or path opens again and the board talks (and boots,
    where opening resets it); a pyserial object also reopens with ``open()``."""
    first = backend.open()
    wait_alive(backend, first)
    first.close()
    second = backend.open()
    wait_alive(backend, second)
    second.close()
    if hasattr(second, "open"):
        second.open()
        wait_alive(backend, second)
        second.close()


def test_recording_port_logs_exactly_what_went_through() -> None:
    """``RecordingPort``: with a writer thread and a reader (1-byte, in_waiting and
    timed reads, then a read blocked until another thread closes the port), the
    recording holds every byte written and every byte read, in order."""
    from wcdrive.transports.recording import RecordingPort

    before = set(threading.enumerate())
    port = RecordingPort(serial.serial_for_url(f"wcsim://?speed={SPEED}", timeout=0.05))
    written: list[bytes] = []
    got: list[bytes] = []
    # After hello the board takes unframed stops only (strict framing): 60 of them
    # answer nothing, so the 3-answers-a-tick budget leaves the last frame's ACK in.
    items = [HELLO, *(frame(encode_wheel(0.3, 0.3), seq) for seq in range(1, 6)),
             (encode_cmdvel(0.0, 0.0) + b"\n") * 60, frame(encode_wheel(0.4, 0.4), 99)]

    def writer() -> None:
        for item in items:
            assert port.write(item) == len(item)
            written.append(item)
            time.sleep(0.02)

    writing = threading.Thread(target=writer, name="recording-writer")
    writing.start()
    try:
        for chunk in (lambda: 1, lambda: max(1, port.in_waiting), lambda: 4096):
            t_end = time.monotonic() + 0.3
            while time.monotonic() < t_end:
                data = port.read(chunk())
                if data:
                    got.append(data)
        writing.join(10)
        while b"ACK:99\r\n" not in b"".join(got):
            assert time.monotonic() < t_end + 15, b"".join(got)[-300:]
            got.append(port.read(4096))
        port.timeout = None
        closer = threading.Timer(0.3, port.close)
        closer.start()
        got.append(port.read(100_000))          # woken by the close
        closer.join()
    finally:
        port.close()
        writing.join(10)
        assert_no_new_threads(before)
    assert port.recording.sent_bytes == b"".join(written)
    assert port.recording.received_bytes == b"".join(got)
    for log in (port.recording.sent, port.recording.received):
        assert all(data for _, data in log)
        times = [t for t, _ in log]
        assert times == sorted(times)
