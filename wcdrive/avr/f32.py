"""binary32 arithmetic as avr-gcc 5.4 and avr-libc's fplib compute it.

``float`` and ``double`` are both IEEE binary32 on the AVR. For binary32 operands,
one IEEE double operation rounded once to binary32 is the correctly rounded binary32
result of + - * / (53 >= 2*24 + 2), which is what avr-libc returns, except:

- multiplication whose exact product is below 2**-126: ``__mulsf3x`` shifts its
  48-bit product right to denormalise it and drops the bits shifted out, so the
  sticky bit misses them (``mul`` models the integer path);
- division whose quotient is subnormal: ``__divsf3x`` denormalises a truncated
  quotient and loses sticky bits (``div`` models it);
- NaN results: ``__fp_nan`` loads only the top two bytes, 0xFFC0, and leaves the low
  two bytes of the first operand: a NaN result is 0xFFC0xxxx, xxxx from ``a``;
- float to integer outside the range (undefined in C): ``__fixsfsi`` gives INT32_MIN
  for NaN, inf and |x| >= 2**31; ``__fixunssfsi`` gives 0 for NaN, inf and
  |x| >= 2**32, and wraps negative values modulo 2**32.

Comparisons (``__cmpsf2``, ``__gesf2``, ``__unordsf2``) are IEEE's, so the port
compares Python floats. See docs/avr-arithmetic.md for the sweep that checks all of
this on the AVR.
"""

from __future__ import annotations

import logging
import math
import os
import struct
from pathlib import Path
from types import ModuleType

from wcdrive._util import native

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


#: ``f32`` as defined here, for the functions below: they stay pure Python (the
#: reference) when the C fast path replaces the module's names.
_round = f32


def bits(x: float) -> int:
    """The binary32 encoding of ``x`` (which must already be a binary32 value)."""
    return _U32.unpack(_pack(x))[0]


def from_bits(word: int) -> float:
    """The binary32 value whose encoding is the low 32 bits of ``word``."""
    return _unpack(_U32.pack(word & 0xFFFFFFFF))[0]


def _nan(a: float) -> float:
    """avr-libc's NaN result: 0xFFC0 over the low 16 bits of the first operand."""
    return from_bits(0xFFC00000 | (bits(a) & 0xFFFF))


def add(a: float, b: float) -> float:
    """``a + b`` as ``__addsf3``: correctly rounded; NaN as ``_nan``."""
    r = a + b
    return _nan(a) if r != r else _round(r)


def sub(a: float, b: float) -> float:
    """``a - b`` as ``__subsf3``: correctly rounded; NaN as ``_nan``."""
    r = a - b
    return _nan(a) if r != r else _round(r)


def mul(a: float, b: float) -> float:
    """``a * b`` as avr-libc's ``__mulsf3`` computes it: correctly rounded unless the
    exact product is below 2**-126 (see ``_mul_small``)."""
    p = a * b                      # exact: 48 significant bits, no double underflow
    if p != p:
        return _nan(a)
    if p == 0.0 or abs(p) >= MIN_NORMAL:   # zero operand, normal, overflow
        return _round(p)
    return _mul_small(a, b)


def _split(word: int) -> tuple[int, int]:
    """``__fp_splitA``: (exponent 1..254, 24-bit mantissa) of a finite nonzero value;
    subnormals get exponent 1 and no hidden bit."""
    exponent = (word >> 23) & 0xFF
    mantissa = word & 0x7FFFFF
    if exponent == 0:
        return 1, mantissa
    return exponent, mantissa | 0x800000


def _mul_small(a: float, b: float) -> float:
    """``__mulsf3x`` + ``__fp_round`` for finite nonzero operands, bit for bit."""
    wa, wb = bits(a), bits(b)
    sign = (wa ^ wb) & 0x80000000
    ea, ma = _split(wa)
    eb, mb = _split(wb)
    product = ma * mb                  # rA2.rA1.rA0.rAE.ZH.ZL, 48 bits
    e = ea + eb - 127
    if e < 0:
        if e < -24:
            return from_bits(sign)     # __fp_szero
        product >>= -e                 # lsr/ror: the bits shifted out of ZL are lost
        e = 0
    elif e > 0:
        while not product & (1 << 47):     # normalise, down to exponent 0 at most
            product <<= 1
            e -= 1
            if e == 0:
                break
        if e >= 254:
            return from_bits(sign | 0x7F800000)
    word = (e << 23) + (product >> 24)     # the hidden bit carries into the exponent
    guard = (product >> 23) & 1
    if guard and (product & 0x7FFFFF or word & 1):   # __fp_round, ties to even
        word += 1
    return from_bits(sign | word)


_TWO_MIN_NORMAL = 2.0 * MIN_NORMAL


def div(a: float, b: float) -> float:
    """``a / b`` as avr-libc's ``__divsf3`` computes it."""
    try:
        q = a / b
    except ZeroDivisionError:
        return _div_by_zero(a, b)
    if q != q:
        return _nan(a)
    if abs(q) >= _TWO_MIN_NORMAL or q == 0.0:   # normal, inf or zero
        return _round(q)
    return _div_subnormal(a, b)


def _div_by_zero(a: float, b: float) -> float:
    if a == 0.0 or math.isnan(a):
        return _nan(a)
    negative = (math.copysign(1.0, a) < 0) != (math.copysign(1.0, b) < 0)
    return -math.inf if negative else math.inf


def _div_subnormal(a: float, b: float) -> float:
    """Quotients near or below the smallest normal: avr-libc's denormalisation."""
    negative = (a < 0) != (b < 0)
    na, da = abs(a).as_integer_ratio()
    nb, db = abs(b).as_integer_ratio()
    num, den = na * db, da * nb        # the exact quotient num / den
    # Normalise: quotient = (q + frac) * 2**(e - 149) with 2**23 <= q < 2**24.
    e = num.bit_length() - den.bit_length() + 126
    while True:
        s = 149 - e
        n, d = (num << s, den) if s >= 0 else (num, den << -s)
        if n < d << 23:
            e -= 1
        elif n >= d << 24:
            e += 1
        else:
            break
    q, r = divmod(n, d)
    extra = 0x00 if 2 * r < d else 0x80 if 2 * r == d else 0xFF
    if e >= 0:
        return _round(a / b)  # normal: the rounding below is exact rounding
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
    return _round(float(n))


def to_int_trunc(x: float) -> int:
    """``(long)x`` as ``__fixsfsi``: truncation toward zero; INT32_MIN for NaN, inf and
    |x| >= 2**31. (``(int)x`` is its low 16 bits.)"""
    if x != x or abs(x) >= 2.0**31:
        return -(2**31)
    return int(x)


def to_u32(x: float) -> int:
    """``(unsigned long)x`` as ``__fixunssfsi``: truncation of |x|, negated modulo 2**32
    for negative x; 0 for NaN, inf and |x| >= 2**32."""
    if x != x or abs(x) >= 2.0**32:
        return 0
    return int(x) & 0xFFFFFFFF


def constrain(x: float, lo: float, hi: float) -> float:
    """Arduino's macro: ``((x)<(lo)?(lo):((x)>(hi)?(hi):(x)))`` (NaN passes through)."""
    return lo if x < lo else (hi if x > hi else x)


# ---- the C fast path ----------------------------------------------------------------
#: The functions with a C fast path (csrc/f32_fast.c), in ``_bind``'s order.
FAST_NAMES = ("f32", "add", "sub", "mul", "div", "from_int")
#: The Python definitions above: the reference, and where the fast path sends every
#: case it does not compute itself (a non-float operand, NaN, subnormal results).
reference = {name: globals()[name] for name in FAST_NAMES}
_FAST_SOURCE = Path(__file__).resolve().parent / "csrc" / "f32_fast.c"


def load_fast() -> ModuleType | None:
    """The C fast path bound to ``reference``: the one the install built, else built on
    first use (``wcdrive._util.native``); None without either (no compiler, no Python
    headers, no writable cache), or with ``WCDRIVE_PURE_F32=1`` in the environment (the
    Python functions only)."""
    if os.environ.get("WCDRIVE_PURE_F32", "") not in ("", "0"):
        native.record("binary32", "Python (WCDRIVE_PURE_F32)")
        return None
    module = native.prebuilt("wcdrive.avr._f32_fast", _FAST_SOURCE)
    how = "built at install"
    if module is None:
        try:
            module = native.load_extension(_FAST_SOURCE, "_f32_fast", ("-O2", "-ffp-contract=off"))
            how = "built at first use"
        except (native.BuildError, OSError) as exc:     # OSError: no writable cache, for one
            logging.getLogger(__name__).warning("binary32 in pure Python (slower): %s", exc)
            native.record("binary32", f"Python ({exc})".splitlines()[0])
            return None
    module._bind(*(reference[name] for name in FAST_NAMES))
    native.record("binary32", how)
    return module


#: The loaded fast path, or None (``load_fast``). Its functions replace the module's
#: names, so ``from wcdrive.avr.f32 import mul`` gets the C one when there is one.
fast = load_fast()
if fast is not None:
    globals().update({name: getattr(fast, name) for name in FAST_NAMES})
