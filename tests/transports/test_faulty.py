"""``FaultyPort``: each fault does what it says and nothing more, reproducibly from its
seed; over an in-memory port (the board is the test) and, once, under a session."""

from __future__ import annotations

import random

import pytest
import serial

from tests.transports.fakeport import FakePort
from wcdrive.transports.faulty import UNPLUGGED, FaultyPort
from wcdrive.transports.port import Port

LINES = b"".join(b"ENC:%d,0\r\nACK:%d\r\n" % (i, i) for i in range(200))


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def rig(seed: int = 0) -> tuple[FaultyPort, FakePort, Clock]:
    clock = Clock()
    inner = FakePort()
    return FaultyPort(inner, seed=seed, clock=clock), inner, clock


def read_all(port: FaultyPort) -> bytes:
    out = bytearray()
    while chunk := port.read(4096):
        out += chunk
    return bytes(out)


def bit_errors(a: bytes, b: bytes) -> int:
    assert len(a) == len(b)
    return sum(bin(x ^ y).count("1") for x, y in zip(a, b, strict=True))


def test_without_faults_the_bytes_pass_as_they_come() -> None:
    port, inner, _ = rig()
    assert isinstance(port, Port)
    inner.feed(b"ENC:1,")                           # half a line: passed on as it is
    assert port.in_waiting == 6
    assert port.read(100) == b"ENC:1,"
    port.write(b"$1:hello*ABCD\n")
    assert inner.written == [b"$1:hello*ABCD\n"]
    assert port.tx.passed == 14 and port.rx.passed == 6


def test_drop_loses_the_matching_lines_count_times() -> None:
    port, inner, _ = rig()
    rule = port.rx.drop(match=rb"^ACK:", count=2)
    inner.feed(b"ENC:1\r\nACK:1\r\nACK:2\r\nENC:2\r\nACK:3\r\n")
    assert read_all(port) == b"ENC:1\r\nENC:2\r\nACK:3\r\n"
    assert rule.hits == [(b"ACK:1\r\n", None), (b"ACK:2\r\n", None)] and rule.count == 0


def test_a_line_is_judged_once_its_end_came() -> None:
    port, inner, _ = rig()
    port.rx.drop(match=rb"^ACK:")
    inner.feed(b"ENC:1\r\nAC")
    assert read_all(port) == b"ENC:1\r\n"           # the head of the ACK waits
    inner.feed(b"K:1\r\nENC:2\r\n")
    assert read_all(port) == b"ENC:2\r\n"


def read_ahead() -> FaultyPort:
    """A port judging by the line that read a whole line, of which the host took 4 bytes."""
    port, inner, _ = rig()
    port.lines = True
    inner.feed(b"ENC:12345\r\n")
    assert port.read(4) == b"ENC:"
    return port


def test_a_read_smaller_than_a_line_leaves_the_rest_for_the_next() -> None:
    port = read_ahead()
    assert port.in_waiting == 7
    assert port.read(100) == b"12345\r\n"


def test_a_byte_read_waits_for_the_rest_of_its_line() -> None:
    """With rules on rx, ``read(1)`` does not return empty while the line is still
    coming in: it reads on until a line is done."""
    port, inner, _ = rig()
    port.rx.drop(match=rb"^ACK:")
    inner.feed(b"ENC:1\r\n")
    assert port.read(1) == b"E"


def test_a_random_drop_is_seeded() -> None:
    def run(seed: int) -> bytes:
        port, inner, _ = rig(seed)
        port.rx.drop(0.25)
        inner.feed(LINES)
        return read_all(port)

    kept = run(7).count(b"\n")
    assert 250 < kept < 350                         # of 400 lines, a quarter lost
    assert run(7) == run(7) and run(7) != run(8)


def test_flip_changes_exactly_its_bits_and_not_the_line_end() -> None:
    port, inner, _ = rig(3)
    rule = port.rx.flip(bits=3, match=rb"^ENC:")
    inner.feed(LINES)
    got = read_all(port).splitlines(keepends=True)
    sent = LINES.splitlines(keepends=True)
    assert len(got) == len(sent)
    for a, b in zip(sent, got, strict=True):
        assert b.endswith(b"\r\n") or b"\n" not in b[:-1]
        assert bit_errors(a, b) == (3 if a.startswith(b"ENC:") else 0), (a, b)
    assert len(rule.hits) == 200


def test_flip_keeps_to_the_group_of_its_pattern() -> None:
    port, inner, _ = rig()
    port.tx.flip(bits=2, match=rb"^\$\d+:(\w+)\*")
    for i in range(50):
        port.write(b"$%d:hello*1234\n" % i)
    for i, data in enumerate(inner.written):
        head = b"$%d:" % i
        assert data.startswith(head) and data.endswith(b"*1234\n")
        assert bit_errors(data[len(head):-6], b"hello") == 2


def test_tx_drop_and_edit_act_per_write() -> None:
    port, inner, _ = rig()
    port.tx.drop(match=rb"estop", count=1)
    edit = port.tx.edit(lambda data: data.replace(b"reset", b"RESET"))
    for data in (b"estop\n", b"estop\n", b"reset\n"):
        assert port.write(data) == len(data)
    assert inner.written == [b"estop\n", b"RESET\n"]
    assert edit.hits == [(b"estop\n", b"estop\n"), (b"reset\n", b"RESET\n")]


def test_rx_delay_holds_a_line_and_what_follows_it() -> None:
    port, inner, clock = rig()
    port.rx.delay(0.2, match=rb"^ACK:")
    inner.feed(b"ENC:1\r\nACK:1\r\nENC:2\r\n")
    assert read_all(port) == b"ENC:1\r\n"           # the ACK waits, and the link keeps order
    clock.now = 0.19
    assert read_all(port) == b""
    clock.now = 0.2
    assert read_all(port) == b"ACK:1\r\nENC:2\r\n"


def test_tx_delay_sends_a_write_at_the_first_call_past_its_time() -> None:
    port, inner, clock = rig()
    port.tx.delay(0.5, count=1)
    port.write(b"late\n")
    port.write(b"next\n")                            # behind the late one
    assert inner.written == []
    clock.now = 0.5
    assert port.in_waiting == 0
    assert inner.written == [b"late\n", b"next\n"]
    assert port.tx.passed == 10


@pytest.mark.parametrize("tx,rx", [(True, True), (True, False), (False, True)])
def test_a_cut_loses_its_directions_until_restored(tx: bool, rx: bool) -> None:
    port, inner, _ = rig()
    inner.feed(b"ENC:0\r\nENC:")                    # some of it read before the cut
    assert port.read(3) == b"ENC"
    port.cut(tx=tx, rx=rx)
    port.write(b"x:1,t:0,\n")
    inner.feed(b"1\r\nENC:2\r\n")
    assert port.is_open
    got = read_all(port)
    assert got == (b"" if rx else b":0\r\nENC:1\r\nENC:2\r\n")
    assert inner.written == ([] if tx else [b"x:1,t:0,\n"])
    port.restore()
    port.write(b"stop\n")
    inner.feed(b"ENC:3\r\n")
    assert read_all(port) == b"ENC:3\r\n" and inner.written[-1] == b"stop\n"


def test_a_partial_cut_sends_a_random_head_of_the_next_write() -> None:
    port, inner, _ = rig(5)
    port.cut(partial=True)
    line = b"$7:x:0.800,t:0.000,*1A2B\n"
    port.write(line)
    port.write(line)
    assert len(inner.written) == 1
    head = inner.written[0]
    assert 1 <= len(head) < len(line) and line.startswith(head)
    assert len(head) == random.Random(5).randrange(1, len(line))


def test_unplugged_every_call_raises_and_the_bytes_meanwhile_are_lost() -> None:
    port, inner, _ = rig()
    port.unplug()
    inner.feed(b"ENC:1\r\n")
    for call in (lambda: port.read(1), lambda: port.write(b"x\n"), lambda: port.in_waiting,
                 port.flush):
        with pytest.raises(serial.SerialException, match="disconnected"):
            call()
    assert inner.written == []
    assert port.replug() == b"ENC:1\r\n"
    inner.feed(b"ENC:2\r\n")
    assert read_all(port) == b"ENC:2\r\n"
    assert UNPLUGGED.startswith("device reports")


def test_the_same_seed_gives_the_same_faults_under_a_session() -> None:
    """Two sessions on ``wcsim://`` behind a port that flips a bit of each tenth line:
    the chair still comes up, and with the same seed the same bits of the same lines
    are hit. The board is paced by the wall clock, so how many lines come before the
    hello differs from run to run (and those are unframed, of another length): the
    compared rule starts once the handshake is done, on a port of its own, where every
    line is a framed one of one length."""
    import wcdrive

    hits = []
    for _ in range(2):
        startup = FaultyPort(serial.serial_for_url("wcsim://?speed=10&seed=1", timeout=0.05), seed=1)
        early = startup.rx.flip(rate=0.5, match=rb"^ENC:", count=3)
        port = FaultyPort(startup, seed=2)
        with wcdrive.Wheelchair(port, stop_on_signals=False) as chair:
            chair.wait_for_telemetry(10.0)
            assert chair.wait_for_handshake(10.0) == 4
            while early.count:                  # its flips all made, and read through
                chair.wait_for_telemetry(10.0)
            for _ in range(3):
                chair.wait_for_telemetry(10.0)
            startup.rx.clear()
            rule = port.rx.flip(rate=0.1, match=rb"^ENC:[^#]*#", count=5)
            while rule.count:
                chair.wait_for_telemetry(10.0)
        assert all(after is not None and len(after) == len(rule.hits[0][0]) for _, after in rule.hits)
        hits.append([bytes(a ^ b for a, b in zip(before, after or b"", strict=True))
                     for before, after in rule.hits])
    assert hits[0] == hits[1] and len(hits[0]) == 5


def test_a_cut_of_a_port_judged_by_the_line_keeps_lines_whole() -> None:
    """``lines=True`` (or rules on rx): what the board sent during the cut is lost by
    the line; the line under way at the restore arrives whole."""
    port, inner, _ = rig()
    port.lines = True
    inner.feed(b"ENC:1\r\nENC:2")
    assert read_all(port) == b"ENC:1\r\n"
    port.cut(tx=False)
    inner.feed(b"2\r\nENC:3")
    assert read_all(port) == b""
    port.restore()
    inner.feed(b"3\r\nENC:4\r\n")
    assert read_all(port) == b"ENC:33\r\nENC:4\r\n"


def test_without_lines_a_cut_loses_bytes_as_they_come() -> None:
    port, inner, _ = rig()
    port.cut(tx=False)
    inner.feed(b"ENC:1\r\nENC:")
    assert read_all(port) == b""
    port.restore()
    inner.feed(b"2\r\n")
    assert read_all(port) == b"2\r\n"               # the tail of a line, as a cable gives it


class Trickle(FakePort):
    """A port without a timeout on which the board's bytes come a chunk at a time:
    ``read(size)`` waits (takes chunks) until it has ``size`` bytes."""

    def __init__(self, chunks: list[bytes]) -> None:
        super().__init__(timeout=None)
        self.chunks = chunks

    def read(self, size: int = 1) -> bytes:
        while len(self.incoming) < size and self.chunks:
            self.feed(self.chunks.pop(0))
        return super().read(size)


def test_a_read_by_the_line_waits_for_size_bytes_without_a_timeout() -> None:
    """Not the 7 bytes of the first whole line: ``size`` bytes, as the port's read."""
    port = FaultyPort(Trickle([b"ENC:1\r\n", b"ENC:2\r\n", b"ENC:3\r\n"]), lines=True)
    assert port.read(10) == b"ENC:1\r\nENC"
    assert port.read(4) == b":2\r\n"


def test_read_ahead_is_lost_with_a_cut() -> None:
    """Bytes of whole lines read from the board but not yet by the host were on their
    way: a cut loses them."""
    port = read_ahead()
    port.cut(tx=False)
    assert read_all(port) == b""


def test_a_closed_port_raises_though_it_read_ahead() -> None:
    port = read_ahead()
    port.close()
    with pytest.raises(serial.SerialException):
        port.read(1)
