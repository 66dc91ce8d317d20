"""Arduino's ``Print`` number formatting (ArduinoCore-avr 1.8.7, ``Print.cpp``)."""

from __future__ import annotations

import functools
import math

from wcdrive.avr.f32 import div, f32, mul

_OVF = 4294967040.0


def print_long(n: int) -> bytes:
    """``Print::print(long)`` in base 10."""
    if n < 0:
        return b"-" + str((-n) & 0xFFFFFFFF).encode()
    return str(n).encode()


def print_unsigned(n: int) -> bytes:
    """``Print::print(unsigned long)`` in base 10 (``n`` taken mod 2**32)."""
    return str(n & 0xFFFFFFFF).encode()


@functools.cache
def _rounding(digits: int) -> float:
    """``rounding = 0.5; for (i < digits) rounding /= 10.0;`` in binary32."""
    rounding = 0.5
    for _ in range(digits):
        rounding = div(rounding, 10.0)
    return rounding


def print_float(number: float, digits: int = 2) -> bytes:
    """``Print::printFloat(number, digits)`` with binary32 arithmetic throughout."""
    if number != number:
        return b"nan"
    if number == math.inf or number == -math.inf:
        return b"inf"
    if number > _OVF or number < -_OVF:
        return b"ovf"
    sign = b""
    if number < 0.0:
        sign = b"-"
        number = -number
    number = f32(number + _rounding(digits))
    int_part = int(number) & 0xFFFFFFFF
    remainder = f32(number - f32(float(int_part)))
    if digits <= 0:
        return b"%s%d" % (sign, int_part)
    fraction = []
    for _ in range(digits):
        remainder = mul(remainder, 10.0)
        to_print = int(remainder) & 0xFFFF
        fraction.append(b"%d" % to_print)
        remainder = f32(remainder - float(to_print))
    return b"%s%d.%s" % (sign, int_part, b"".join(fraction))
