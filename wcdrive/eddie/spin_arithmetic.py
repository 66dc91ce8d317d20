"""Spin's integer arithmetic, as the Eddie board's firmware computes: every value a
signed 32-bit long (``s32``), ``~`` and ``~~`` sign-extending a byte and a word
(``sx8``, ``sx16``), ``/`` truncating toward zero (``sdiv``), ``//`` with the
dividend's sign (``smod``), ``^^`` the square root of the unsigned 32-bit value
(``ssqrt``), ``#>``/``<#`` limits (``clamp``), ``OutputHex`` (``hexw``), and the
Propeller's clock (``CLKFREQ``).

Python's integers are unbounded and its ``//`` and ``%`` round toward minus
infinity, where Spin wraps at 32 bits and truncates toward zero; a wrap, a rounding
or a sign that differs from the Propeller's would change a reply or a motor power, so
the model computes on Spin values through these functions.
"""

from __future__ import annotations

import math

CLKFREQ = 80_000_000


def s32(v: int) -> int:
    """Wraps to a signed 32-bit long, as every Spin variable is."""
    v &= 0xFFFFFFFF
    return v - (1 << 32) if v & 0x80000000 else v


def sx8(v: int) -> int:
    """Spin's ``~``: sign-extend bit 7."""
    v &= 0xFF
    return v - 0x100 if v & 0x80 else v


def sx16(v: int) -> int:
    """Spin's ``~~``: sign-extend bit 15."""
    v &= 0xFFFF
    return v - (1 << 16) if v & 0x8000 else v


def sdiv(a: int, b: int) -> int:
    """Spin's ``/``: truncates toward zero. Division by zero gives 0 here (the source
    never guards it; docs/eddie.md)."""
    if b == 0:
        return 0
    q = abs(a) // abs(b)
    return s32(q if (a >= 0) == (b >= 0) else -q)


def smod(a: int, b: int) -> int:
    """Spin's ``//``: the remainder, with the sign of the dividend."""
    if b == 0:
        return 0
    return s32(a - sdiv(a, b) * b)


def ssqrt(a: int) -> int:
    """Spin's ``^^``: integer square root of the value read as unsigned 32-bit."""
    return math.isqrt(a & 0xFFFFFFFF)


def clamp(v: int, lo: int, hi: int) -> int:
    """``lo #> v <# hi``."""
    return min(max(v, lo), hi)


def hexw(value: int, digits: int) -> bytes:
    """``OutputHex``: the low ``digits`` nibbles, upper case."""
    return f"{value & ((1 << (4 * digits)) - 1):0{digits}X}".encode()

