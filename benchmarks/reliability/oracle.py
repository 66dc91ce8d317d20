"""The oracle: which input is valid, decided from protocol/PROTOCOL.md ("Framing and
commands"), not from the parser."""

from __future__ import annotations

import re

from wcdrive.protocol.codec import crc16

from .common import CMD_MAX_LEN, MAX_ANGULAR, MAX_LINEAR, MAX_WHEEL, SEQ_MAX

# ---- the oracle: valid input, from protocol/PROTOCOL.md ------------------------------
_EOL = re.compile(rb"[\r\n]")


def split_commands(line: bytes) -> list[bytes | None]:
    """The commands a line makes, by the framing rules (None: an overlong command)."""
    out: list[bytes | None] = []
    for seg in _EOL.split(line):
        p, n = 0, len(seg)
        while p < n:
            if seg[p] == 0x24:                              # a frame: to the line end
                out.append(seg[p:] if n - p <= CMD_MAX_LEN else None)
                break
            commas, i = 0, p
            while True:
                q = seg.find(b",", i)
                last = q if q >= 0 else n - 1
                if last >= p + CMD_MAX_LEN:                 # byte p+63 finds the buffer full
                    out.append(None)
                    k = p + CMD_MAX_LEN
                    if seg[k] == 0x2C:
                        p = k + 1
                    else:                                   # dropped up to the next comma
                        q2 = seg.find(b",", k + 1)
                        p = n if q2 < 0 else q2 + 1
                    break
                if q < 0:
                    out.append(seg[p:])
                    p = n
                    break
                commas += 1
                buf = seg[p:q + 1]
                need = 2 if buf[:1] in (b"r", b"x") else 8 if buf[:4] == b"ppm:" else 0
                if need == 0 or commas >= need:
                    out.append(buf)
                    p = q + 1
                    break
                i = q + 1
    return out


_U = rb"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_WHEEL = re.compile(rb"r[pn](" + _U + rb"),l[pn](" + _U + rb"),?")
_CMDVEL = re.compile(rb"x:([+-]?" + _U + rb"),t:([+-]?" + _U + rb"),?")
_PPM = re.compile(rb"ppm:\d{1,4}(?:,\d{1,4}){7},?")
_OTHER = re.compile(rb"hello|estop|reset|get:[\x21-\x7e]*|set:[\x21-\x7e]*")
_FRAME = re.compile(rb"\$(\d{1,5}):.*\*([0-9A-F]{4})", re.S)


def _within(text: bytes, limit: float) -> bool:
    return abs(float(text)) <= limit * (1 + 1e-6)


def frame_valid(cmd: bytes) -> bool:
    """A v3 frame with a well-formed seq and the right CRC-16, at most 63 bytes."""
    m = _FRAME.fullmatch(cmd)
    return (m is not None and len(cmd) <= CMD_MAX_LEN and int(m[1]) <= SEQ_MAX
            and crc16(cmd[1:-5]) == int(m[2], 16))


def v1_valid(cmd: bytes) -> bool:
    """A well-formed version-1 command (or a valid frame)."""
    m = _CMDVEL.fullmatch(cmd)
    if m:
        return _within(m[1], MAX_LINEAR) and _within(m[2], MAX_ANGULAR)
    m = _WHEEL.fullmatch(cmd)
    if m:
        return _within(m[1], MAX_WHEEL) and _within(m[2], MAX_WHEEL)
    return bool(_PPM.fullmatch(cmd) or _OTHER.fullmatch(cmd)) or frame_valid(cmd)


def line_valid(line: bytes, strict: bool) -> bool:
    """Does the line hold a valid command (after hello: a valid frame)?"""
    check = frame_valid if strict else v1_valid
    return any(c is not None and check(c) for c in split_commands(line))


