"""Strict framing, end to end: a host that said hello sends 10,000 motion frames, each
with 1 to 3 flipped bits or a burst of up to 16 bits anywhere in the line (the ``$``
included), over ``wcsim://`` (the port and the plant) and over ``wcavr://`` (the
compiled firmware in simavr with the plant behind its pins; the first 2,500 of them at
the fast depth, all 10,000 at the thorough one). Not one is ACKed, and
the TLM PWM never leaves 0. And the legacy rules: without hello, the seed host's
unframed line drives; after hello it is refused."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest
import serial

from tests.conftest import thorough
from wcdrive.protocol.codec import frame

FRAMES = 10_000
#: simavr takes about 1 s of CPU per 1,000 frames: the fast depth sends the first 2,500.
FIRMWARE_FRAMES = FRAMES if thorough() else 2_500
TLM = re.compile(rb"TLM:\d+,\d+,\d+,(\d+),(\d+),")


def corrupted_frames(n: int, seed: int) -> list[bytes]:
    """``n`` motion frames, each with a random 1-3 bit flip or a 2-16 bit burst."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        v = rng.uniform(0.3, 2.0)
        line = bytearray(frame(b"x:%.3f,t:%.3f," % (v, rng.uniform(-1, 1)), 100 + i % 60000))
        bits = 8 * (len(line) - 1)
        if rng.random() < 0.7:
            for k in rng.choice(bits, int(rng.integers(1, 4)), replace=False):
                line[k // 8] ^= 0x80 >> (k % 8)
        else:
            width = int(rng.integers(2, 17))
            start = int(rng.integers(0, bits - width + 1))
            pattern = int(rng.integers(0, 1 << width)) | 1 | (1 << (width - 1))
            for j in range(width):
                if pattern >> j & 1:
                    k = start + j
                    line[k // 8] ^= 0x80 >> (k % 8)
        line[-1:] = b"\n"
        out.append(bytes(line))
    return out


def _read_for(port: serial.SerialBase, seconds: float) -> bytes:
    data = b""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        data += port.read(port.in_waiting or 1)
    return data


def _until(port: serial.SerialBase, marker: bytes, seconds: float = 20.0) -> bytes:
    data = b""
    end = time.monotonic() + seconds
    while marker not in data and time.monotonic() < end:
        data += port.read(port.in_waiting or 1)
    assert marker in data, data[-300:]
    return data


def _attack(url: str, n_frames: int = FRAMES) -> tuple[bytes, int]:
    port = serial.serial_for_url(url, timeout=0.05)
    try:
        _until(port, b"ENC:")
        port.write(frame(b"hello", 1))
        received = _until(port, b"HELLO:3,")
        frames = corrupted_frames(n_frames, seed=7)
        for i in range(0, n_frames, 200):
            port.write(b"".join(frames[i:i + 200]))
            received += port.read(port.in_waiting)
        total = len(frame(b"hello", 1)) + len(b"".join(frames))
        end = time.monotonic() + 300
        while time.monotonic() < end:                   # until the board has taken every byte
            received += port.read(port.in_waiting or 1)
            rx = [int(m) for m in re.findall(rb"TLM:\d+,(\d+),", received[-400:])]
            if rx and rx[-1] >= total:
                break
        received += _read_for(port, 0.2)
        port.write(frame(b"get:kp_l", 2))              # a good frame in a fresh tick: answered
        received += _until(port, b"ACK:2\r\n", seconds=20)
        received += _read_for(port, 0.2)
    finally:
        port.close()
    return received, len(b"".join(frames))


def _check(received: bytes) -> None:
    acks = re.findall(rb"ACK:(\d+)", received)
    assert acks == [b"1", b"2"], acks[:10]            # the hello and the last good frame
    pwm = TLM.findall(received)
    assert len(pwm) > 20
    assert all(a == b"0" and b == b"0" for a, b in pwm), pwm
    assert b"MODE:CMDVEL" in received and b"MODE:WHEEL" not in received and b"MODE:PPM" not in received


def test_no_corrupted_frame_moves_the_simulated_chair() -> None:
    received, sent = _attack("wcsim://?speed=20")
    assert sent > 200_000
    _check(received)


@pytest.mark.simavr
def test_no_corrupted_frame_moves_the_firmware(elf) -> None:
    received, sent = _attack(f"wcavr://{elf}?realtime=0", FIRMWARE_FRAMES)
    assert sent > 20 * FIRMWARE_FRAMES
    _check(received)


def test_legacy_lines_drive_only_before_hello() -> None:
    port = serial.serial_for_url("wcsim://?speed=10", timeout=0.05)
    try:
        _until(port, b"ENC:")
        port.write(b"x:0.5,t:0.0,")                      # the seed host: no newline, no hello
        _until(port, b"MODE:CMDVEL")
        port.write(frame(b"hello", 1))
        _until(port, b"HELLO:3,")
        port.write(b"x:0.5,t:0.0,\n")
        assert b"ERR:unframed" in _until(port, b"ERR:unframed")
        port.write(b"," + frame(b"rp1.0,lp1.0,", 5)[1:])  # the $ flipped to ,
        after = _until(port, b"ERR:unframed") + _read_for(port, 0.5)
        assert b"ACK:5" not in after and b"MODE:WHEEL" not in after
    finally:
        port.close()
