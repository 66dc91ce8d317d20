"""The serial protocol's codec: pure functions and an incremental line decoder, no I/O.

Host to board:  ``encode_cmdvel(v, w)`` -> ``b"x:0.500,t:0.100,"`` (the seed host's
format), ``encode_wheel(right, left)`` -> ``b"rp5.000,lp3.000,"``, ``encode_ppm``.
Board to host:  ``LineDecoder.feed(data)`` returns the complete lines' messages:
``Feedback``, ``Error``, ``Event``, ``Boot`` or ``Unknown``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

MAX_LINEAR = 2.68
MAX_ANGULAR = 9.4
MAX_WHEEL = 17.59
MAX_LINE = 256


def _finite(name: str, value: float, limit: float) -> float:
    value = float(value)
    if math.isnan(value) or math.isinf(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if abs(value) > limit:
        raise ValueError(f"{name}={value} is outside ±{limit}")
    return value


def encode_cmdvel(linear: float, angular: float) -> bytes:
    """``x:<m/s>,t:<rad/s>,`` with 3 decimals, as the seed's ``wc_control`` node sends it."""
    v = _finite("linear", linear, MAX_LINEAR)
    w = _finite("angular", angular, MAX_ANGULAR)
    return f"x:{v:.3f},t:{w:.3f},".encode()


def encode_wheel(right: float, left: float) -> bytes:
    """``r<p|n><rad/s>,l<p|n><rad/s>,``: the sign as ``p``/``n``."""
    r = _finite("right", right, MAX_WHEEL)
    l_ = _finite("left", left, MAX_WHEEL)
    return (f"r{'n' if r < 0 else 'p'}{abs(r):.3f},l{'n' if l_ < 0 else 'p'}{abs(l_):.3f},").encode()


def encode_ppm(channels: list[int] | tuple[int, ...]) -> bytes:
    if len(channels) != 8:
        raise ValueError("a PPM frame has 8 channels")
    for c in channels:
        if not isinstance(c, int) or not 0 <= c <= 9999:
            raise ValueError(f"PPM channel {c!r} is not an integer 0..9999 (microseconds)")
    return ("ppm:" + ",".join(str(c) for c in channels) + ",").encode()


@dataclass(frozen=True)
class Feedback:
    """``ENC:l,r,VEL:l,r,MODE:m``: raw counts (left mirrored) and rad/s (2 decimals)."""

    count_left: int
    count_right: int
    vel_left: float
    vel_right: float
    mode: str


@dataclass(frozen=True)
class Error:
    reason: str


@dataclass(frozen=True)
class Event:
    name: str


@dataclass(frozen=True)
class Boot:
    text: str


@dataclass(frozen=True)
class Unknown:
    line: bytes


Message = Feedback | Error | Event | Boot | Unknown

_NUMBER = rb"-?(?:\d+(?:\.\d*)?|nan|inf|ovf)"
_FEEDBACK = re.compile(
    rb"ENC:(-?\d+),(-?\d+),VEL:(" + _NUMBER + rb"),(" + _NUMBER + rb"),MODE:(WHEEL|CMDVEL|PPM)")


def _float(text: bytes) -> float:
    t = text.lstrip(b"-")
    if t == b"ovf":
        value = math.inf
    else:
        value = float(t)
    return -value if text.startswith(b"-") else value


def parse_line(line: bytes) -> Message:
    """One line without its ``\\r\\n``."""
    m = _FEEDBACK.fullmatch(line)
    if m:
        return Feedback(int(m[1]), int(m[2]), _float(m[3]), _float(m[4]), m[5].decode())
    if line.startswith(b"ERR:"):
        return Error(line[4:].decode("ascii", "replace"))
    if line.startswith(b"EVT:"):
        return Event(line[4:].decode("ascii", "replace"))
    if line.startswith(b"BOOT:"):
        return Boot(line[5:].decode("ascii", "replace"))
    return Unknown(line)


class LineDecoder:
    """Incremental: feed bytes as they come, get the messages of complete lines.
    A line longer than ``MAX_LINE`` bytes is dropped (as ``Unknown``) to bound memory."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Message]:
        self._buf += data
        out: list[Message] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > MAX_LINE:
                    out.append(Unknown(bytes(self._buf)))
                    self._buf.clear()
                return out
            line = bytes(self._buf[:i]).rstrip(b"\r")
            del self._buf[:i + 1]
            out.append(parse_line(line))
