"""Protocol v4 on the board's side (the port; the differential holds the firmware to it):
after ``hello:4`` every line the board sends is a frame, ``<text>#NN*CCCC\\r\\n``, whose
CRC holds and whose counter is one more than the last line's; before it, and after a
plain ``hello``, the lines are as in v3. protocol/vectors.toml pins the bytes on both
sides."""

from __future__ import annotations

from hypothesis import example, given
from hypothesis import strategies as st

from wcdrive.firmware import constants as C
from wcdrive.firmware.final_control import Firmware
from wcdrive.protocol.codec import LINE_COUNTER_WRAP, board_unframe, frame
from wcdrive.testing.strategies import byte_streams


def _lines(data: bytes) -> list[bytes]:
    assert data.endswith(b"\r\n") or not data
    return data[:-2].split(b"\r\n") if data else []


def _drive(fw: Firmware, chunks: list[bytes], start: int) -> bytes:
    """Each chunk fed, then a tick 50 ms on, with the wheels turning."""
    out = bytearray()
    now = start
    for i, chunk in enumerate(chunks):
        out += fw.feed(chunk)
        now += C.CONTROL_PERIOD_MS
        out += fw.tick(now, 37 * i, -41 * i)
    return bytes(out)


def _outputs(fw: Firmware, chunks: list[bytes], start: int) -> list[tuple[bool, bool, int, bytes]]:
    """Each chunk fed, then a tick 50 ms on, with the wheels turning: for each feed and
    each tick, whether the board framed its lines before and after it, how many hellos
    it was given, and what it sent."""
    outputs = []
    now = start
    for i, chunk in enumerate(chunks):
        for hellos, step in ((chunk.count(b"hello"), lambda c=chunk: fw.feed(c)),
                             (0, lambda n=now + C.CONTROL_PERIOD_MS, i=i: fw.tick(n, 37 * i, -41 * i))):
            before = bool(fw.state.linesFramed)
            out = step()
            outputs.append((before, bool(fw.state.linesFramed), hellos, out))
        now += C.CONTROL_PERIOD_MS
    return outputs


@given(st.lists(byte_streams(), min_size=1, max_size=8))
@example([frame(b"hello", 2), b"x:0.5,t:0.1,", frame(b"hello:4", 3), frame(b"get:kp", 4)])
def test_after_hello4_every_line_is_a_frame_in_turn(chunks: list[bytes]) -> None:
    """Whatever the host sends after hello:4 (frames, seed lines, garbage, plain hellos
    and hello:4 among them), each line the board sends while it frames is a good frame
    whose counter is one more than the last frame's (the counter runs on across a
    plain spell); after a plain hello the lines are plain v3 until a hello:4 again.
    A line the output budget drops takes no counter (test_a_line_over_budget_...)."""
    fw = Firmware()
    head = fw.feed(frame(b"hello:4", 1))
    assert board_unframe(_lines(head)[0]) == (_lines(head)[0][:-8], 0)
    expected = 0
    for framed_before, framed_after, hellos, out in [(True, True, 0, head), *_outputs(fw, chunks, 0)]:
        modes = []
        for line in _lines(out):
            unframed = board_unframe(line)
            if unframed is not None:
                assert framed_before or framed_after, line
                assert unframed[1] == expected, line
                expected = (expected + 1) % LINE_COUNTER_WRAP
            else:
                assert not (framed_before and framed_after) and b"#" not in line, line
                assert not line.startswith(b"HELLO:4"), "hello:4 answered unframed"
            if not modes or modes[-1] != (unframed is not None):
                modes.append(unframed is not None)
        assert len(modes) <= 1 + hellos, (modes, out)       # a mode changes only at a hello
    assert fw.state.lineCounter == expected


def test_before_hello_the_lines_are_the_seeds() -> None:
    """A host that never says hello gets v1/v3 lines, no frame, no counter (its neutral
    command first, which stands two ticks: then it drives)."""
    fw = Firmware()
    out = _drive(fw, [b"x:0.000,t:0.000,\n", b"", b"x:0.500,t:0.100,", b"rp05.00,lp03.00,", b""], 0)
    lines = _lines(out)
    assert lines and all(line.startswith(b"ENC:") and b"#" not in line for line in lines)
    assert fw.state.targetR != 0.0                      # driven, not refused
    assert fw.state.linesFramed == 0 and fw.state.lineCounter == 0


def test_a_line_over_budget_takes_no_counter() -> None:
    """The counter counts lines that go: one the output budget drops leaves no gap
    (a gap on the host is a line lost on the way)."""
    fw = Firmware()
    fw.feed(frame(b"hello:4", 1))
    fw.state.txCredit = 0
    fw.state.lastTickTime = C.CONTROL_PERIOD_MS - 5     # 5 ms since: 50 bytes of credit
    before = fw.state.lineCounter
    out = fw.tick(C.CONTROL_PERIOD_MS, 0, 0)
    sent = _lines(out)
    assert fw.state.txDropped == 2 - len(sent) >= 1     # the TLM line did not fit
    assert all(board_unframe(line) for line in sent)
    assert fw.state.lineCounter == (before + len(sent)) % LINE_COUNTER_WRAP
