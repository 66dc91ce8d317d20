"""Protocol v3's CRC-16/XMODEM detects every error of 1, 2 or 3 flipped bits and every
burst of up to 16 bits in a frame of our length: proved exhaustively, and shown to be
a proof that can fail (the v2 XOR checksum fails it).

The CRC (``binascii.crc_hqx(data, 0)``: initial value 0, no final XOR) is linear over
GF(2), so a corrupted payload ``a ^ e`` passes the check exactly when ``crc(e) == 0``,
whatever ``a`` is. ``crc(e)`` is the XOR of the syndromes of its bits (the CRC of a
message with that one bit set), and leading zero bytes do not change a CRC with
initial value 0, so the syndromes of a 63-byte message (the longest line the board
takes) cover every shorter frame too.
"""

from __future__ import annotations

import binascii
import itertools
from collections.abc import Callable

import numpy as np
import pytest

from wcdrive.firmware.final_control import Firmware
from wcdrive.protocol.codec import crc16, frame

LENGTH = 63                     # bytes: WC_CMD_MAX_LEN, the longest line the board takes


def syndromes(check: Callable[[bytes], int], length: int = LENGTH) -> np.ndarray:
    """``check`` of every single-bit error of a ``length``-byte message."""
    out = np.zeros(8 * length, dtype=np.int64)
    for k in range(8 * length):
        e = bytearray(length)
        e[k // 8] = 0x80 >> (k % 8)
        out[k] = check(bytes(e))
    return out


def xor_checksum(data: bytes) -> int:
    """Protocol v2's checksum, for comparison."""
    value = 0
    for b in data:
        value ^= b
    return value


def undetected(check: Callable[[bytes], int], length: int = LENGTH) -> dict[str, int]:
    """How many errors of each kind pass ``check`` (linear, zero on zeros) in a message
    of ``length`` bytes, and so in every shorter one."""
    s = syndromes(check, length)
    bits = 8 * length
    out = {"1 bit": int(np.count_nonzero(s == 0))}
    pairs = s[:, None] ^ s[None, :]
    upper = np.triu(np.ones((bits, bits), dtype=bool), 1)
    out["2 bits"] = int(np.count_nonzero((pairs == 0) & upper))
    # 3 bits i < j < k pass when s[k] == s[i] ^ s[j]: count them through a table of
    # where each syndrome value stands.
    where: dict[int, list[int]] = {}
    for k, v in enumerate(s.tolist()):
        where.setdefault(v, []).append(k)
    three = 0
    for i in range(bits):
        row = (s[i] ^ s[i + 1:]).tolist()
        for offset, v in enumerate(row):
            j = i + 1 + offset
            three += sum(1 for k in where.get(v, ()) if k > j)
    out["3 bits"] = three
    # Bursts: every non-zero error inside a window of 16 bits, at every position.
    bursts = 0
    for start in range(bits):
        width = min(16, bits - start)
        table = np.zeros(1 << width, dtype=np.int64)
        for j in range(width):
            table[1 << j: 1 << (j + 1)] = table[: 1 << j] ^ s[start + j]
        bursts += int(np.count_nonzero(table[1:] == 0))
    out["bursts <= 16 bits"] = bursts
    return out


def test_crc16_xmodem_detects_every_small_error_and_burst() -> None:
    assert undetected(crc16) == {"1 bit": 0, "2 bits": 0, "3 bits": 0, "bursts <= 16 bits": 0}


def test_the_proof_can_fail_on_the_v2_checksum() -> None:
    """The same count finds the errors the v2 XOR checksum missed: two flips in one bit
    column of two bytes."""
    missed = undetected(xor_checksum)
    assert missed["1 bit"] == 0
    assert missed["2 bits"] == 8 * (LENGTH * (LENGTH - 1) // 2)   # same bit, any two bytes
    assert missed["bursts <= 16 bits"] > 0


def test_crc16_is_crc_xmodem() -> None:
    """The check value of CRC-16/XMODEM, and linearity (what the proof relies on)."""
    assert crc16(b"123456789") == 0x31C3
    rng = np.random.default_rng(1)
    for _ in range(200):
        a = bytes(rng.integers(0, 256, LENGTH, dtype=np.uint8))
        e = bytes(rng.integers(0, 256, LENGTH, dtype=np.uint8))
        assert crc16(bytes(x ^ y for x, y in zip(a, e, strict=True))) == crc16(a) ^ crc16(e)
    assert binascii.crc_hqx(bytes(10) + b"x:0.5", 0) == crc16(b"x:0.5")   # leading zeros


@pytest.mark.parametrize("bits", [1, 2, 3])
def test_no_flipped_frame_moves_the_port(bits: int) -> None:
    """Whole lines, ``$`` and CRC digits included: every 1- and 2-bit flip of a motion
    frame, and 20,000 sampled 3-bit flips, sent after hello: none is ACKed, none moves
    the targets."""
    line = frame(b"x:0.500,t:0.200,", 4242)
    positions = range(8 * (len(line) - 1))                      # not the line end
    if bits < 3:
        errors = list(itertools.combinations(positions, bits))
    else:
        rng = np.random.default_rng(3)
        errors = [tuple(rng.choice(len(positions), 3, replace=False)) for _ in range(20_000)]
    base = Firmware()
    base.feed(frame(b"hello", 1))
    for flips in errors:
        corrupted = bytearray(line)
        for k in flips:
            corrupted[k // 8] ^= 0x80 >> (k % 8)
        fw = Firmware(base.state.copy())
        out = fw.feed(bytes(corrupted) + b"\n")
        assert b"ACK:" not in out, (flips, bytes(corrupted))
        assert fw.state.targetL == 0.0 and fw.state.targetR == 0.0, (flips, bytes(corrupted))
