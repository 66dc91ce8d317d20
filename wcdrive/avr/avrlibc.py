"""avr-libc's ``strtod`` (``libc/stdlib/strtod.c``), which is not correctly rounded.

Digits accumulate in a uint32 until it reaches (ULONG_MAX - 9) / 10; later integer
digits only bump the decimal exponent and later fraction digits are dropped. The
uint32 is converted to binary32, then scaled by binary32 powers of ten, largest
first (1e32, 1e16, 1e8, 1e4, 1e2, 1e1 or their reciprocals), rounding each time.
"""

from __future__ import annotations

import math
import re

from wcdrive.avr.f32 import f32, mul

_POW_P10 = tuple(f32(float(f"1e{p}")) for p in (1, 2, 4, 8, 16, 32))
_POW_M10 = tuple(f32(float(f"1e-{p}")) for p in (1, 2, 4, 8, 16, 32))
_OVERFLOW_AT = (0xFFFFFFFF - 9) // 10
_SPACE = b" \t\n\v\f\r"


_PLAIN = re.compile(rb"([+-]?)([0-9]*)(?:\.([0-9]*))?")


def strtod(text: bytes, start: int = 0) -> tuple[float, int]:
    """Parses ``text[start:]`` (stopping at a NUL as C does). Returns the value and
    the index just past the last character used (``start`` when nothing was)."""
    plain = _PLAIN.fullmatch(text, start)
    if plain is not None:
        whole, frac = plain[2], plain[3] or b""
        if 0 < len(whole) + len(frac) <= 9:
            # At most 9 digits: no uint32 overflow, so the value is just the digits.
            return _scale(int(whole + frac), -len(frac), plain[1] == b"-"), len(text)
    return _strtod(text, start)


def _scale(value: int, exp: int, negative: bool) -> float:
    """The end of strtod: to binary32, the sign, then the powers of ten."""
    x = f32(float(value))
    if negative:
        x = -x
    if x != 0:
        table = _POW_M10 if exp < 0 else _POW_P10
        e = -exp if exp < 0 else exp
        index = 5
        power = 32
        while power:
            while e >= power:
                x = mul(x, table[index])   # __mulsf3: not correctly rounded below 2**-126
                e -= power
            index -= 1
            power >>= 1
    return x


def _strtod(text: bytes, start: int) -> tuple[float, int]:
    s = text
    n = len(s)

    def char(i: int) -> int:
        return s[i] if i < n else 0

    i = start
    c = char(i)
    i += 1
    while c in _SPACE and c != 0:
        c = char(i)
        i += 1
    negative = False
    if c == ord("-"):
        negative = True
        c = char(i)
        i += 1
    elif c == ord("+"):
        c = char(i)
        i += 1
    # i - 1 indexes c
    if _match_ci(s, i - 1, b"inf"):
        end = i + 2
        if _match_ci(s, end, b"inity"):
            end += 5
        return (-math.inf if negative else math.inf), end
    if _match_ci(s, i - 1, b"nan"):
        return math.nan, i + 2

    value = 0
    exp = 0
    any_digit = dot = overflow = False
    while True:
        d = (c - 0x30) & 0xFF
        if d <= 9:
            any_digit = True
            if overflow:
                if not dot:
                    exp += 1
            else:
                if dot:
                    exp -= 1
                value = (value * 10 + d) & 0xFFFFFFFF
                if value >= _OVERFLOW_AT:
                    overflow = True
        elif d == ((ord(".") - 0x30) & 0xFF) and not dot:
            dot = True
        else:
            break
        c = char(i)
        i += 1

    if c in (ord("e"), ord("E")):
        c = char(i)
        i += 1
        back = 2
        exp_negative = False
        if c == ord("-"):
            exp_negative = True
            c = char(i)
            i += 1
        elif c == ord("+"):
            c = char(i)
            i += 1
        else:
            back = 1
        d = (c - 0x30) & 0xFF
        if d > 9:
            i -= back
        else:
            e = 0
            while d <= 9:
                if e < 3200:
                    e = e * 10 + d
                c = char(i)
                i += 1
                d = (c - 0x30) & 0xFF
            exp += -e if exp_negative else e

    end = i - 1 if any_digit else start
    return _scale(value, exp, negative and any_digit), end


def _match_ci(s: bytes, i: int, word: bytes) -> bool:
    """``strncasecmp_P(s + i, word, len(word)) == 0``, with C's NUL termination."""
    for k, w in enumerate(word):
        j = i + k
        c = s[j] if 0 <= j < len(s) else 0
        if c == 0 or (c | 0x20) != w:
            return False
    return True
