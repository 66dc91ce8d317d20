"""binary32 arithmetic as avr-gcc 5.4 and avr-libc's fplib compute it.

``float`` and ``double`` are both IEEE binary32 on the AVR. For binary32 operands,
one IEEE double operation rounded once to binary32 is the correctly rounded binary32
result of + - * / (53 >= 2*24 + 2), which is what avr-libc returns, except for
division whose quotient is subnormal: there avr-libc's ``__divsf3x`` denormalises a
truncated 40-bit quotient and loses sticky bits. ``div`` reproduces that path
exactly from the integer long division.
"""

from __future__ import annotations

import math
import struct
from fractions import Fraction

_F32 = struct.Struct("<f")
_U32 = struct.Struct("<I")
_pack = _F32.pack
_unpack = _F32.unpack

MIN_NORMAL = 2.0**-126
SUBNORMAL_QUANTUM = 2.0**-149


def f32(x: float) -> float:
    """Rounds a Python float to the nearest binary32 (ties to even), as a float."""
    try:
        return _unpack(_pack(x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


def bits(x: float) -> int:
    """The binary32 encoding of ``x`` (which must already be a binary32 value)."""
    return _U32.unpack(_pack(x))[0]


def from_bits(word: int) -> float:
    """The binary32 value whose encoding is the low 32 bits of ``word``."""
    return _unpack(_U32.pack(word & 0xFFFFFFFF))[0]


def add(a: float, b: float) -> float:
    """``a + b`` in binary32 (one rounding)."""
    return f32(a + b)


def sub(a: float, b: float) -> float:
    """``a - b`` in binary32 (one rounding)."""
    return f32(a - b)


def mul(a: float, b: float) -> float:
    """``a * b`` in binary32 (one rounding)."""
    return f32(a * b)


_TWO_MIN_NORMAL = 2.0 * MIN_NORMAL


def div(a: float, b: float) -> float:
    """``a / b`` as avr-libc's ``__divsf3`` computes it."""
    try:
        q = a / b
    except ZeroDivisionError:
        return _div_by_zero(a, b)
    if abs(q) >= _TWO_MIN_NORMAL or q == 0.0 or q != q:   # normal, inf, zero or NaN
        return f32(q)
    return _div_subnormal(a, b)


def _div_by_zero(a: float, b: float) -> float:
    if a == 0.0 or math.isnan(a):
        return math.nan
    negative = (math.copysign(1.0, a) < 0) != (math.copysign(1.0, b) < 0)
    return -math.inf if negative else math.inf


def _div_subnormal(a: float, b: float) -> float:
    """Quotients near or below the smallest normal: avr-libc's denormalisation."""
    negative = (a < 0) != (b < 0)
    quotient = abs(Fraction(a)) / abs(Fraction(b))
    # Normalise: quotient = (q + frac) * 2**(e - 149) with 2**23 <= q < 2**24.
    e = quotient.numerator.bit_length() - quotient.denominator.bit_length() + 126
    while True:
        scaled = quotient * Fraction(2) ** (149 - e)
        if scaled < 2**23:
            e -= 1
        elif scaled >= 2**24:
            e += 1
        else:
            break
    q = scaled.numerator // scaled.denominator
    frac = scaled - q
    extra = 0x00 if frac < Fraction(1, 2) else 0x80 if frac == Fraction(1, 2) else 0xFF
    if e >= 0:
        return f32(a / b)  # normal: the rounding below is exact rounding
    shift = -e
    if shift > 24:
        return -0.0 if negative else 0.0
    word = ((q << 16) | (extra << 8)) >> shift   # rA2.rA1.rA0.rAE.ZH, low bits lost
    mantissa = word >> 16
    guard = (word >> 15) & 1
    sticky = word & 0x7FFF
    if guard and (sticky or (mantissa & 1)):
        mantissa += 1
    value = mantissa * SUBNORMAL_QUANTUM
    return -value if negative else value


def neg(a: float) -> float:
    """``-a``: exact, a flip of the sign bit."""
    return -a


def from_int(n: int) -> float:
    """``(float)`` of a 32-bit integer (round to nearest even)."""
    return f32(float(n))


def to_int_trunc(x: float) -> int:
    """``(int)``/``(long)`` of a float in range: truncation toward zero."""
    return int(x)


def to_u32(x: float) -> int:
    """``(unsigned long)`` of a non-negative float below 2**32."""
    return int(x) & 0xFFFFFFFF


def constrain(x: float, lo: float, hi: float) -> float:
    """Arduino's macro: ``((x)<(lo)?(lo):((x)>(hi)?(hi):(x)))`` (NaN passes through)."""
    return lo if x < lo else (hi if x > hi else x)
