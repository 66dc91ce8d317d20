"""The hostile input: valid commands, random lines, mutations of valid ones (R1) and
corruptions of motion frames (R2), each drawn from the caller's ``random.Random``."""

from __future__ import annotations

import random
from collections.abc import Iterator

from wcdrive.firmware.params import PARAMS
from wcdrive.protocol.codec import frame

from .common import SEQ_MAX

# ---- input -----------------------------------------------------------------------
_FORMATS = ("%.3f", "%.3f", "%.3f", "%.2f", "%.1f", "%.4f")


def _number(rng: random.Random, lo: float, hi: float, signed: bool) -> bytes:
    """A non-zero decimal in [lo, hi] (either sign with ``signed``)."""
    while True:
        v = rng.uniform(lo, hi)
        if signed and rng.random() < 0.5:
            v = -v
        text = (rng.choice(_FORMATS) % v).encode()
        if float(text) != 0.0:
            return text


def motion_command(rng: random.Random) -> bytes:
    """A valid command that drives (non-zero targets), well inside every limit."""
    k = rng.random()
    if k < 0.45:
        x = _number(rng, 0.0, 2.6, True)
        t = _number(rng, 0.0, 9.3, True) if rng.random() < 0.8 else b"0"
        return b"x:%s,t:%s," % (x, t)
    if k < 0.8:
        return b"r%c%s,l%c%s," % (rng.choice(b"pn"), _number(rng, 0.01, 17.5, False),
                                   rng.choice(b"pn"), _number(rng, 0.01, 17.5, False))
    channels = [rng.randint(1000, 2000) for _ in range(8)]
    channels[1] = 1500 + rng.choice((-1, 1)) * rng.randint(20, 500)   # stick out of the dead band
    return b"ppm:" + b",".join(b"%d" % c for c in channels) + b","


def stop_command(rng: random.Random) -> bytes:
    """A valid stop: zero targets in any form, or a PPM frame that reports signal loss."""
    k = rng.randrange(4)
    if k == 0:
        return rng.choice([b"x:0,t:0,", b"x:0.000,t:0.000,", b"x:-0.0,t:+0,", b"rp0,ln0.0,",
                           b"rn0.000,lp0,"])
    channels = [rng.randint(1000, 2000) for _ in range(8)]
    channels[1] = rng.randint(1490, 1510)
    channels[3] = rng.randint(1490, 1510)
    if k == 3:
        channels[rng.randrange(8)] = rng.choice([0, 850, 899, 2101, 9999])
    return b"ppm:" + b",".join(b"%d" % c for c in channels) + b","


_SETTABLE = [p for p in PARAMS if p.name != "max_wheel"]   # lowering it would refuse controls


def param_command(rng: random.Random) -> bytes:
    """``get:`` or ``set:`` (in range) of a parameter other than ``max_wheel``."""
    p = rng.choice(_SETTABLE)
    if rng.random() < 0.4:
        return b"get:" + p.name.encode()
    if p.integer:
        value = b"%d" % rng.randint(int(p.low), int(p.high))
    else:
        value = b"%.3f" % rng.uniform(float(p.low) + 0.001, float(p.high) - 0.001)
    return b"set:" + p.name.encode() + b"=" + value


def valid_line(rng: random.Random, strict: bool) -> tuple[str, bytes, bytes]:
    """(kind, content, terminator) of a valid command: a frame after hello (``strict``),
    a bare version-1 command before, newline-less (the seed host's way) or not."""
    r = rng.random()
    if r < 0.7:
        kind, cmd = "drive", motion_command(rng)
    elif strict and r < 0.85:
        kind, cmd = "param", param_command(rng)
    else:
        kind, cmd = "stop", stop_command(rng)
    if strict:
        return kind, frame(cmd, rng.randint(0, SEQ_MAX))[:-1], b"\n"
    return kind, cmd, rng.choice([b"", b"\n", b"\r\n"])


_ALPHABET = b"0123456789.,:-+$*xtrlpnm\r\n ABCDEFabcdef=_eshogk"


def _random_byte(rng: random.Random) -> int:
    return rng.randrange(256) if rng.random() < 0.4 else rng.choice(_ALPHABET)


MUTATIONS = ("flip", "replace", "insert", "delete", "truncate", "duplicate", "splice", "swap",
             "case")


def mutate(rng: random.Random, content: bytes, other: bytes, strict: bool) -> tuple[str, bytes]:
    """A mutation of a valid command's ``content`` (``other``: a second one, to splice)."""
    op = rng.choice(MUTATIONS + (("deframe",) if strict else ()))
    c = bytearray(content)
    n = len(c)
    if op == "flip":
        for _ in range(rng.randint(1, 3)):
            c[rng.randrange(n)] ^= 1 << rng.randrange(8)
    elif op == "replace":
        for _ in range(rng.randint(1, 3)):
            c[rng.randrange(n)] = _random_byte(rng)
    elif op == "insert":
        for _ in range(rng.randint(1, 3)):
            c.insert(rng.randint(0, len(c)), _random_byte(rng))
    elif op == "delete":
        i = rng.randrange(n)
        del c[i:i + rng.choice((1, 1, 2, 3, rng.randint(1, n)))]
    elif op == "truncate":
        c = c[:rng.randrange(n)]
    elif op == "duplicate":
        if rng.random() < 0.3:
            c = c + rng.choice((b"", b",")) + c
        else:
            i = rng.randrange(n)
            j = rng.randint(i + 1, n)
            c[j:j] = c[i:j]
    elif op == "splice":
        c = c[:rng.randint(1, n - 1)] + other[rng.randint(1, len(other) - 1):]
    elif op == "swap":
        i = rng.randrange(n - 1)
        c[i], c[i + 1] = c[i + 1], c[i]
    elif op == "case":
        letters = [i for i, b in enumerate(c) if 0x41 <= (b | 0x20) - 0x20 <= 0x5A]
        c[rng.choice(letters)] ^= 0x20
    else:                                   # deframe: the bare command of a frame
        c = c[c.index(b":") + 1:c.rindex(b"*")]
    if bytes(c) == content:
        c[rng.randrange(n)] ^= 1 << rng.randrange(8)
    return op, bytes(c)


def random_line(rng: random.Random) -> bytes:
    """1 to 90 random bytes (any byte, printable ASCII, or the protocol's characters), then
    ``\\n``."""
    n = rng.choice((rng.randint(1, 8), rng.randint(9, 40), rng.randint(9, 40), rng.randint(41, 90)))
    k = rng.random()
    if k < 0.4:
        body = rng.randbytes(n)
    elif k < 0.7:
        body = bytes(rng.randint(0x21, 0x7E) for _ in range(n))
    else:
        body = bytes(rng.choice(_ALPHABET) for _ in range(n))
    return body + b"\n"


def r1_lines(rng: random.Random, n: int, strict: bool) -> Iterator[tuple[str, bytes]]:
    """``n`` lines as (source, bytes): source "random", "mutated", or the valid kinds
    "drive", "stop", "param"."""
    for _ in range(n):
        r = rng.random()
        if r < 0.30:
            yield "random", random_line(rng)
        elif r < 0.85:
            _, content, _ = valid_line(rng, strict)
            _, other, _ = valid_line(rng, strict)
            yield "mutated", mutate(rng, content, other, strict)[1] + b"\n"
        else:
            kind, content, end = valid_line(rng, strict)
            yield kind, content + end


def cmdvel_command(rng: random.Random) -> bytes:
    """R2's command: ``x:<v>,t:<w>,`` with 3 decimals, as the seed host sends it."""
    return b"x:%.3f,t:%.3f," % (rng.uniform(-2.6, 2.6), rng.uniform(-2.0, 2.0))


CORRUPTIONS = ("1 bit", "2 bits", "3 bits", "burst, CRC bit order", "burst, UART bit order")


def corrupt(rng: random.Random, line: bytes) -> tuple[str, bytes]:
    """(class, line) with 1-3 flipped bits or a 2-16 bit burst anywhere but the final
    ``\\n``. Bits are numbered MSB first in each byte (the CRC's order) or LSB first
    (the UART's, for the second kind of burst)."""
    out = bytearray(line)
    bits = 8 * (len(line) - 1)
    kind = rng.choice(CORRUPTIONS)
    if kind.startswith("burst"):
        width = rng.randint(2, 16)
        start = rng.randint(0, bits - width)
        pattern = rng.getrandbits(width) | 1 | (1 << (width - 1))
        positions = [start + j for j in range(width) if pattern >> j & 1]
    else:
        positions = rng.sample(range(bits), int(kind[0]))
    uart = kind.endswith("UART bit order")
    for k in positions:
        out[k // 8] ^= (1 << (k % 8)) if uart else (0x80 >> (k % 8))
    return kind, bytes(out)


