"""The C fast path of the port's binary32 arithmetic (wcdrive/avr/csrc/f32_fast.c)
against the Python functions it stands in for (``f32.reference``), bit for bit: the
common case it computes itself and every case it hands back. The float sweep
(tests/avr/test_fp_sweep.py) checks the same functions against the AVR."""

from __future__ import annotations

import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from wcdrive.avr import f32 as F
from wcdrive.firmware import commands, control, motion

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(F.fast is None, reason="the C fast path did not build (a warning says why)")

BINARY = ("add", "sub", "mul", "div")
words = st.integers(0, 2**32 - 1)
SPECIAL = [0.0, -0.0, math.inf, -math.inf, F.MIN_NORMAL, -F.MIN_NORMAL, F.SUBNORMAL_QUANTUM,
           3 * F.SUBNORMAL_QUANTUM, 2.0**-125, 1.0, -1.0, 0.1, F.from_bits(0x7F7FFFFF),
           F.from_bits(0xFF7FFFFF), F.from_bits(0x7FC00000), F.from_bits(0xFFC01234),
           F.from_bits(0x7F800001), 2.0**64, 2.0**-64]


def same(x: float, y: float) -> bool:
    """The same Python float bit for bit (a NaN's payload too), compared as the double
    it is: a result the fast path forgot to round to binary32 differs."""
    return isinstance(x, float) and isinstance(y, float) and struct.pack("<d", x) == struct.pack("<d", y)


def fast(name: str):
    return getattr(F.fast, name)


@given(a=words, b=words)
@example(a=0x00000005, b=0x3DCCCCCD)    # a subnormal product avr-libc rounds low
@example(a=0x7F800000, b=0xFF800000)    # inf - inf: NaN from the first operand
@example(a=0x00000000, b=0x80000000)
def test_binary_operations_agree(a: int, b: int) -> None:
    x, y = F.from_bits(a), F.from_bits(b)
    for name in BINARY:
        assert same(fast(name)(x, y), F.reference[name](x, y)), (name, hex(a), hex(b))


def test_special_values_agree() -> None:
    for x in SPECIAL:
        assert same(fast("f32")(x), F.reference["f32"](x)), x
        for y in SPECIAL:
            for name in BINARY:
                assert same(fast(name)(x, y), F.reference[name](x, y)), (name, x, y)


def test_a_million_random_pairs_agree() -> None:
    """Uniform words and products/quotients near 2**-126 (the cases handed back)."""
    rng = np.random.default_rng(7)
    a = rng.integers(0, 2**32, 500_000, dtype=np.uint64).astype(np.uint32)
    b = rng.integers(0, 2**32, 500_000, dtype=np.uint64).astype(np.uint32)
    small = rng.integers(0x00000001, 0x0F000000, 500_000, dtype=np.uint64).astype(np.uint32)
    near_one = rng.integers(0x3E000000, 0x41000000, 500_000, dtype=np.uint64).astype(np.uint32)
    pairs = (np.concatenate((a, small)), np.concatenate((b, near_one)))
    with np.errstate(invalid="ignore"):      # signalling NaNs become quiet: payload kept
        xs = pairs[0].view(np.float32).astype(np.float64).tolist()
        ys = pairs[1].view(np.float32).astype(np.float64).tolist()
    for name in BINARY:
        got = np.array(list(map(fast(name), xs, ys)), dtype=np.float64).view(np.uint64)
        want = np.array(list(map(F.reference[name], xs, ys)), dtype=np.float64).view(np.uint64)
        bad = np.flatnonzero(got != want)            # the doubles, bit for bit
        assert not bad.size, (name, hex(int(pairs[0][bad[0]])), hex(int(pairs[1][bad[0]])))


@given(x=st.floats(allow_nan=True, allow_infinity=True))
@example(x=3.4028235677973366e38)       # rounds to the largest finite binary32
@example(x=3.4028236e38)                 # rounds to infinity (struct: OverflowError)
@example(x=1e-46)
def test_rounding_agrees(x: float) -> None:
    assert same(fast("f32")(x), F.reference["f32"](x))


@given(n=st.one_of(st.integers(-(2**31), 2**32), st.integers(-(2**70), 2**70)))
@example(n=2**53 + 1)
@example(n=16_777_217)
def test_int_conversion_agrees(n: int) -> None:
    assert same(fast("from_int")(n), F.reference["from_int"](n))


def test_what_is_not_a_float_goes_to_the_python_function() -> None:
    """Integers, bools and float subclasses: the Python function decides (the same
    answer, the same errors)."""
    class Sub(float):
        pass

    for a, b in ((3, 0.5), (True, 2.0), (Sub(1.5), 2.0), (2**40, 3)):
        for name in BINARY:
            assert same(fast(name)(a, b), F.reference[name](a, b)), (name, a, b)
    with pytest.raises(TypeError):
        fast("mul")("1", 2.0)
    with pytest.raises(TypeError):
        fast("add")(1.0)


def test_the_port_uses_the_fast_path() -> None:
    """The firmware modules bound the C functions at import (``from f32 import mul``)."""
    for module in (control, commands, motion):
        for name in ("add", "mul", "div"):
            if hasattr(module, name):
                assert getattr(module, name) is getattr(F.fast, name), (module.__name__, name)


def test_the_python_path_gives_the_same_run() -> None:
    """A scenario on the port with ``WCDRIVE_PURE_F32=1`` (no C fast path) and with it:
    the same digest of every tick's state and every byte."""
    code = ("import json, hashlib; from tests.support.sim_digest import digest; from wcdrive.avr import f32; "
            "from wcdrive.sim import runner, scenario; "
            "d = json.dumps(digest(runner.run(scenario.load('fault_encoder_noise_200k'))), sort_keys=True); "
            "print(f32.fast is None, hashlib.sha256(d.encode()).hexdigest())")
    outs = []
    for pure in ("1", "0"):
        env = {**os.environ, "WCDRIVE_PURE_F32": pure}
        run = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True,
                             timeout=300)
        assert run.returncode == 0, run.stderr
        outs.append(run.stdout.split())
    assert outs[0][0] == "True" and outs[1][0] == "False"
    assert outs[0][1] == outs[1][1]


def test_the_reference_is_pure_python() -> None:
    """The Python functions round through their own ``f32`` (``_round``), not the C one
    that replaced the module's name: with the fast path loaded they are still the
    independent reference."""
    assert F._round is F.reference["f32"] and F.f32 is F.fast.f32
    assert F.reference["mul"].__globals__["_round"] is F.reference["f32"]


def test_an_unwritable_cache_needs_no_build(tmp_path: Path) -> None:
    """Where nothing can be built (the cache is not writable), the library imports and a
    simulated chair runs on the helpers the install built. Without those, the binary32
    operations and the plant run in pure Python, a warning saying why:
    tests/meta/test_wheel.py's install without a compiler shows that."""
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("")
    code = ("import wcdrive.host.wheelchair; from wcdrive.avr import f32; from wcdrive.plant import Plant; "
            "p = Plant(); p.advance(5); print(f32.fast is None, p.uses_kernel, f32.mul(0.1, 3.0))")
    env = {**os.environ, "WCDRIVE_CACHE": str(not_a_dir / "cache")}
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["False", "True", repr(F.mul(0.1, 3.0))]
