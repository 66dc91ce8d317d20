"""Protocol v4's board lines (``codec.board_frame``: ``<text>#<NN>*<CCCC>``): the CRC
detects every error of 1, 2 or 3 flipped bits and every burst of up to 16 bits in a line
as long as the board's line buffer, proved as for the host's frames
(tests/protocol/test_crc.py, whose count this reuses); and ``board_unframe`` believes no
flipped, cut or spliced line, checked on the lines themselves.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tests.protocol.test_crc import undetected, xor_checksum
from wcdrive.firmware import constants as C
from wcdrive.protocol.codec import LINE_COUNTER_WRAP, board_frame, board_unframe, crc16

#: bytes: the board's line buffer (LineBuffer::buf_, ``TX_LINE_MAX``), the longest line it
#: can send; the CRC covers less (not its ``*CCCC\r\n``), and the proof at this length
#: covers that.
LENGTH = C.TX_LINE_MAX

TLM = b"TLM:4294967295,4294967295,4294967295,65535,65535,65535,255,255,255,511,65535,65535,8191"
ENC = b"ENC:-2147483648,2147483647,VEL:-17.59,17.59,MODE:CMDVEL"


def test_the_board_lines_crc_detects_every_small_error_and_burst() -> None:
    assert undetected(crc16, LENGTH) == {"1 bit": 0, "2 bits": 0, "3 bits": 0, "bursts <= 16 bits": 0}


def test_the_proof_at_board_length_can_fail() -> None:
    assert undetected(xor_checksum, LENGTH)["2 bits"] > 0


def test_a_board_line_round_trips_and_keeps_its_text_first() -> None:
    line = board_frame(ENC, 0x2A)
    assert line.startswith(ENC + b"#2A*") and line.endswith(b"\r\n") and len(line) == len(ENC) + 10
    assert board_unframe(line[:-2]) == (ENC, 0x2A)
    assert [board_unframe(board_frame(b"EVT:WATCHDOG", n)[:-2]) for n in (0, 255)] == [
        (b"EVT:WATCHDOG", 0), (b"EVT:WATCHDOG", 255)]
    with pytest.raises(ValueError):
        board_frame(ENC, LINE_COUNTER_WRAP)


@pytest.mark.parametrize("bits", [1, 2, 3])
def test_no_flipped_board_line_is_believed(bits: int) -> None:
    """Every 1- and 2-bit flip of the longest TLM line, counter and CRC digits included,
    and 20,000 sampled 3-bit flips: none unframes."""
    line = board_frame(TLM, 0x7F)[:-2]
    positions = range(8 * len(line))
    if bits < 3:
        errors = list(itertools.combinations(positions, bits))
    else:
        rng = np.random.default_rng(3)
        errors = [tuple(rng.choice(len(positions), 3, replace=False)) for _ in range(20_000)]
    for flips in errors:
        corrupted = bytearray(line)
        for k in flips:
            corrupted[k // 8] ^= 0x80 >> (k % 8)
        assert board_unframe(bytes(corrupted)) is None, (flips, bytes(corrupted))


def test_no_cut_or_spliced_board_line_is_believed() -> None:
    """The head of one line joined to the tail of a later one, at every cut (what a full
    receive ring that drops bytes makes), and every line cut short: none unframes."""
    first = board_frame(ENC, 3)[:-2]
    later = board_frame(b"ENC:-1234,5678,VEL:0.50,0.51,MODE:CMDVEL", 5)[:-2]
    for i in range(1, len(first)):
        for j in range(1, len(later)):
            spliced = first[:i] + later[j:]
            if spliced != later:
                assert board_unframe(spliced) is None, spliced
        assert board_unframe(first[:i]) is None
