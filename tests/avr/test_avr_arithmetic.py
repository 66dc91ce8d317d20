"""The port's binary32 arithmetic, strtod and printFloat against the AVR itself
(firmware/fpcheck in simavr), bit for bit."""

from __future__ import annotations

import math
import random
import struct

import pytest
from hypothesis import assume, example, given
from hypothesis import strategies as st

from wcdrive.avr import f32 as F
from wcdrive.avr.arduino_print import print_float
from wcdrive.avr.avrlibc import strtod
from wcdrive.hil.fpcheck import AvrMath

pytestmark = pytest.mark.simavr

binary32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
tiny = st.integers(1, 2**23 - 1).map(lambda m: m * 2.0**-149)  # subnormals


def b32(x: float) -> int:
    return struct.unpack("<I", struct.pack("<f", x))[0]


@pytest.fixture(scope="module")
def avr():
    m = AvrMath()
    yield m
    m.close()


@given(a=binary32, b=binary32)
@example(a=1.0, b=3.0)
def test_add_sub_mul_match(avr, a: float, b: float) -> None:
    for op, fn in (("add", F.add), ("sub", F.sub), ("mul", F.mul)):
        assert b32(fn(a, b)) == b32(avr.binary(op, a, b)), (op, a, b)


@given(a=binary32, b=binary32.filter(lambda x: x != 0.0))
def test_division_matches(avr, a: float, b: float) -> None:
    assert b32(F.div(a, b)) == b32(avr.binary("div", a, b))


@given(a=st.one_of(tiny, binary32.filter(lambda x: 0 < abs(x) < 1e-30)),
       b=st.floats(0.5, 64.0, width=32))
@example(a=1.4e-45, b=2.0)
@example(a=2.0**-126, b=3.0)
@example(a=3 * 2.0**-149, b=2.0)
def test_division_with_subnormal_quotients(avr, a: float, b: float) -> None:
    """avr-libc denormalises a truncated quotient: not always correctly rounded."""
    assert b32(F.div(a, b)) == b32(avr.binary("div", a, b)), (a, b)


def test_subnormal_division_differs_from_correct_rounding_somewhere(avr) -> None:
    """The reason div() has its own path: quotients below 2**-125 where avr-libc is
    not the correctly rounded result (about 0.8% of random cases), reproduced."""
    rng = random.Random(1)
    differing = []
    while len(differing) < 100:
        a = F.f32(rng.randint(1, 2**24) * 2.0**-149 * 2 ** rng.randint(0, 30))
        b = F.f32(rng.uniform(1.0, 1000.0))
        if b32(F.div(a, b)) != b32(F.f32(a / b)):
            differing.append((a, b))
    for a, b in differing:
        assert b32(avr.binary("div", a, b)) == b32(F.div(a, b)), (a, b)


decimal_strings = st.one_of(
    st.from_regex(r"\A[+-]?[0-9]{0,25}(\.[0-9]{0,25})?([eE][+-]?[0-9]{1,3})?\Z"),
    st.floats(width=32, allow_nan=False, allow_infinity=False).map(repr),
    st.decimals(allow_nan=False, allow_infinity=False, places=6).map(str),
    st.text(alphabet="0123456789.eE+-infatyINFATY ", max_size=20),
)


@given(text=decimal_strings)
@example(text="3.14159")
@example(text="2.68")
@example(text="7.0000005")
@example(text="1.00000005960464477539")
@example(text="429496728")
@example(text="4294967295999")
@example(text="0.000000000000000000000000000000000000000000001")
@example(text="1e-46")
@example(text="-infinity")
@example(text="nan(")
def test_strtod_matches(avr, text: str) -> None:
    data = text.encode()
    assume(len(data) < 79)
    value, used = strtod(data)
    avr_value, avr_used = avr.strtod(data)
    assert used == avr_used, text
    if math.isnan(avr_value):
        assert math.isnan(value)
    else:
        assert b32(value) == b32(avr_value), text


def test_strtod_is_not_correctly_rounded() -> None:
    assert b32(strtod(b"3.14159")[0]) == 0x40490FCF     # correct rounding: 0x40490FD0
    assert b32(strtod(b"2.68")[0]) == 0x402B851E        # 0x402B851F


@given(x=st.one_of(binary32, st.floats(-300.0, 300.0, width=32)), digits=st.integers(0, 6))
@example(x=6.28318, digits=2)
@example(x=2.675, digits=2)
@example(x=-0.005, digits=2)
@example(x=1e10, digits=2)
@example(x=4294967040.0, digits=2)
@example(x=-0.0, digits=2)
def test_print_float_matches(avr, x: float, digits: int) -> None:
    assert print_float(F.f32(x), digits) == avr.print_float(x, digits)


def test_print_float_special_values(avr) -> None:
    for x in (math.inf, -math.inf, math.nan):
        assert print_float(x, 2) == avr.print_float(x, 2)


@given(n=st.integers(-(2**31), 2**31 - 1))
@example(n=2**24 + 1)
@example(n=-(2**31))
def test_int_to_float_matches(avr, n: int) -> None:
    assert b32(F.from_int(n)) == b32(avr.from_int(n))
