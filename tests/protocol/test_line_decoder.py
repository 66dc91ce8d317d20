"""``LineDecoder`` gives the same messages however the stream is cut into chunks: its
one-whole-line shortcut (a ``bytes`` chunk that is exactly one line, nothing held)
against its general path (``bytearray`` chunks never take the shortcut)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from wcdrive.protocol.codec import MAX_LINE, LineDecoder

LINES = [b"ENC:-12,34,VEL:-0.50,0.51,MODE:CMDVEL\r\n", b"ENC:1,2,VEL:ovf,-inf,MODE:PPM\r\n",
         b"TLM:1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\r\n", b"EVT:WATCHDOG\r\n", b"ACK:7\r\n",
         b"ENC:1,2,VEL:0.0BOOT:final_control,EXTERNAL\r\n", b"BOOT:final_control,POWER_ON\r\n", b"\r\n",
         b"\n", b"garbage\r\r\n", b"x" * (MAX_LINE + 5), b"ENC:1,2", b"\r"]


@given(st.lists(st.sampled_from(LINES), max_size=12), st.lists(st.integers(0, 60), max_size=20))
def test_chunks_give_the_same_messages(lines: list[bytes], cuts: list[int]) -> None:
    stream = b"".join(lines)
    chunks, at = [], 0
    for cut in cuts:
        chunks.append(stream[at:at + cut])
        at += cut
    chunks.append(stream[at:])
    by_line = [line for line in stream.splitlines(keepends=True)]     # whole lines, as a board sends
    for pieces in (chunks, by_line):
        fast, general = LineDecoder(), LineDecoder()
        got = [m for piece in pieces for m in fast.feed(piece)]
        want = [m for piece in pieces for m in general.feed(bytearray(piece))]
        assert got == want
