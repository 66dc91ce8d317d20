"""Protocol v4 on the host's side, end to end: a board (``wcsim://``, the simulated
board behind a pty, and the firmware in simavr, ``wcavr://``) behind a
``FaultyPort`` that corrupts what the board sends (1 to 3 flipped bits a line, lost
lines, lines spliced where a run of bytes was lost). The host believes no corrupted
line: every message it acts on is one the board sent; it counts what it dropped
(``chair.link_stats``) and its pose stays the one the good lines give."""

from __future__ import annotations

import contextlib
import random
import time
from collections.abc import Callable, Iterator

import pytest
import serial

import wcdrive
from wcdrive.boards.sim_board import SimulatedBoard
from wcdrive.protocol.codec import Corrupt, LineDecoder, Message, Unknown
from wcdrive.transports.faulty import FaultyPort
from wcdrive.transports.pty_bridge import PtyBridge


class Tap(FaultyPort):
    """A ``FaultyPort`` over a board's port (``wcsim://`` unless given) that keeps every
    byte the board sent, before the faults."""

    def __init__(self, seed: int, port: serial.SerialBase | None = None) -> None:
        super().__init__(port or serial.serial_for_url("wcsim://?speed=1", timeout=0.05), seed=seed,
                         lines=True)
        self.sent = bytearray()

    def on_read(self, data: bytes) -> bytes:
        self.sent += data
        return super().on_read(data)


def _splice(rng: random.Random):
    """Cuts a line short, its line end too: its head joins the next line."""
    def edit(unit: bytes) -> bytes:
        return unit[:rng.randrange(1, max(2, len(unit) - 2))]
    return edit


def _believed(chair: wcdrive.Wheelchair) -> list[Message]:
    got: list[Message] = []
    session = chair._session
    handle = session._handle

    def spy(now: float, msg: object) -> None:
        if not isinstance(msg, (Corrupt, Unknown)):
            got.append(msg)                 # type: ignore[arg-type]
        handle(now, msg)
    session._handle = spy                   # type: ignore[method-assign]
    return got


#: The simulated board's speed (times the wall clock) in the drive through corruption;
#: the firmware in simavr runs at real time.
SIM_SPEED = 2.0


@contextlib.contextmanager
def _board(backend: str, request: pytest.FixtureRequest
           ) -> Iterator[tuple[serial.SerialBase, Callable[[], tuple[float, float, float]], float]]:
    """The board's port, its ground truth (the plant's pose) and its speed."""
    if backend == "wcsim":
        port = serial.serial_for_url(f"wcsim://?speed={SIM_SPEED:g}", timeout=0.05)
        yield port, port.board.pose, SIM_SPEED
    elif backend == "pty":
        board = SimulatedBoard(speed=SIM_SPEED).start()
        bridge = PtyBridge(board).start()
        try:
            yield serial.Serial(bridge.path, 115200, timeout=0.05), board.pose, SIM_SPEED
        finally:
            bridge.close()
            board.close()
    else:
        elf = request.getfixturevalue("elf")
        port = serial.serial_for_url(f"wcavr://{elf}", timeout=0.05)
        yield port, port.board.pose, 1.0


@pytest.mark.parametrize(("backend", "seed"), [
    ("wcsim", 1), ("wcsim", 2), ("pty", 3), pytest.param("simavr", 4, marks=pytest.mark.simavr)])
def test_no_corrupted_board_line_is_believed(backend: str, seed: int, request: pytest.FixtureRequest) -> None:
    """A 3 s drive with a third of the board's lines damaged: every message the host
    acted on is one the board sent (so every ACK it believed answers a request it
    made), no fault is believed, every line is accounted for (good, bad CRC, spliced
    or lost: as many as the board sent), and once the chair stands the pose is the
    plant's to a millimetre, as on a clean link."""
    rng = random.Random(seed)
    with _board(backend, request) as (inner, truth_pose, speed):
        port = Tap(seed, inner)
        _drive_through_corruption(port, rng, truth_pose, speed)


def _drive_through_corruption(port: Tap, rng: random.Random,
                              truth_pose: Callable[[], tuple[float, float, float]],
                              speed: float = 1.0) -> None:
    """3 s of the board's clock driving, a command every 0.05 s of the wall clock
    (0.1 s of the board's at twice its speed), then 1.5 s of it at rest."""
    chair = wcdrive.Wheelchair(port)
    try:
        believed = _believed(chair)
        assert chair.wait_for_handshake() == 4
        chair.wait_for_telemetry()
        chair.wait_for_neutral()            # booted: it drives after a neutral command
        flips = [port.rx.flip(bits=1, rate=0.1), port.rx.flip(bits=3, rate=0.1)]
        port.rx.drop(rate=0.05)
        splice = port.rx.edit(_splice(rng), match=rb"^(ENC|TLM)")
        splice.rate = 0.1
        deadline = time.monotonic() + 3.0 / speed
        while time.monotonic() < deadline:
            chair.set_velocity(0.4, 0.1)                    # raises on a believed fault
            time.sleep(0.05)
        chair.stop()
        time.sleep(1.5 / speed)                             # at rest
        pose = chair.odometry.pose
        x, y, _ = truth_pose()
        faults, events = chair.faults, list(chair.events)
        # The decoder counts the lines a spliced or lost tail took only at the next
        # good line: the faults end and one comes, so that every line is accounted for.
        port.rx.clear()
        good, end = chair.link_stats.good, time.monotonic() + 2.0
        while chair.link_stats.good == good and time.monotonic() < end:
            time.sleep(0.01)
    finally:
        chair.close()
    stats = chair.link_stats
    truth = [m for m in LineDecoder().feed(bytes(port.sent)) if not isinstance(m, Unknown)]
    lines = bytes(port.sent).count(b"\n")
    assert all(not isinstance(m, Corrupt) for m in truth)
    assert believed, "nothing got through"
    sent = set(truth)
    assert not [m for m in believed if m not in sent]
    assert stats.bad_crc > 0 and stats.spliced > 0 and stats.lost > 0, stats
    # A flip that makes a line end cuts one line in two bad ones.
    cuts = sum(after.count(b"\n") - before.count(b"\n") for rule in flips
               for before, after in rule.hits if after is not None)
    assert lines <= stats.total <= lines + cuts, (stats, lines, cuts)
    assert faults == () and not any(e.startswith("FAULT") for e in events), events
    assert ((pose.x - x) ** 2 + (pose.y - y) ** 2) ** 0.5 < 0.002, (pose, x, y)


def test_a_board_that_refuses_hello4_is_a_protocol_error() -> None:
    """A v3 board answers ``hello:4`` ``NAK:<seq>,syntax`` (it knows no such command):
    the host says at once that the firmware is too old, rather than driving a board
    whose lines it cannot check. (The board here is v4; the host's hello is rewritten
    to ``hello:9``, which it refuses just as a v3 board refuses ``hello:4``.)"""
    from wcdrive.protocol.codec import frame

    port = Tap(0)

    def older(unit: bytes) -> bytes:
        seq = int(unit[1:unit.index(b":")])
        return frame(b"hello:9", seq)

    port.tx.edit(older, match=rb"^\$\d+:hello:4\*")
    chair = wcdrive.Wheelchair(port)
    try:
        started = time.monotonic()
        with pytest.raises(wcdrive.WcdriveProtocolError, match="v3 or older"):
            chair.wait_for_handshake()
        assert time.monotonic() - started < 1.0         # the first refusal ends it
    finally:
        chair.close()
