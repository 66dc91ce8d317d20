"""The binary32 sweep (wcdrive.hil.fpsweep): every float operation the sketch calls, on
the AVR in simavr against the port's wcdrive.avr.f32, bit for bit.

Under the ``ci`` profile each operation runs FULL_PAIRS pairs (>= 10**6); the default
profile runs a slice. docs/avr-arithmetic.md has the figures.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.conftest import thorough
from wcdrive._util.resources import firmware_dir
from wcdrive.avr import f32 as F
from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.hil import fpsweep
from wcdrive.hil.fpcheck import BATCH, AvrMath

pytestmark = pytest.mark.simavr

FULL_PAIRS = 1_000_000
SLICE_PAIRS = 20_000

def st_sign(m: int) -> int:
    return 0x80000000 if m & 1 else 0


words = st.one_of(
    st.integers(0, 2**32 - 1),
    st.floats(width=32).map(F.bits),
    st.integers(0, 2**23).map(lambda m: m | st_sign(m)),      # subnormals and zeros
    st.sampled_from(fpsweep.SPECIAL_WORDS),
)


@pytest.fixture(scope="module")
def avr():
    m = AvrMath()
    yield m
    m.close()


@pytest.mark.parametrize("op", fpsweep.OPERATIONS)
def test_sweep(avr: AvrMath, op: str) -> None:
    n = FULL_PAIRS if thorough() else SLICE_PAIRS
    result = fpsweep.sweep(avr, op, n, seed=1)
    assert result.count >= n
    assert result.mismatches == 0, result.describe()


@pytest.mark.parametrize("op", fpsweep.OPERATIONS)
@given(data=st.data())
def test_hypothesis_chosen_pairs(avr: AvrMath, op: str, data: st.DataObject) -> None:
    pairs = data.draw(st.lists(st.tuples(words, words), min_size=1, max_size=BATCH))
    result = fpsweep.SweepResult(op)
    fpsweep.check(avr, op, [a for a, _ in pairs], [b for _, b in pairs], result)
    assert result.mismatches == 0, result.describe()


@pytest.mark.parametrize("op", ["mul", "div"])
def test_the_sweep_reaches_avr_libc_s_rounding_quirks(avr: AvrMath, op: str) -> None:
    """The targeted sets hold pairs where avr-libc is not IEEE's correct rounding:
    without them, a port that rounds correctly would pass."""
    result = fpsweep.sweep(avr, op, SLICE_PAIRS, seed=2)
    assert result.mismatches == 0, result.describe()
    assert result.not_ieee >= 10, result.describe()


@pytest.mark.parametrize("op", ["add", "sub", "mul", "div", "floatsisf"])
def test_the_python_reference_against_the_avr(avr: AvrMath, op: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """With the C fast path loaded (``wcdrive/avr/csrc/f32_fast.c``) the sweep runs it;
    the pure Python functions it hands the uncommon cases to, and that run alone with
    ``WCDRIVE_PURE_F32=1`` or without a compiler, are swept here on the same slice."""
    for name in ("add", "sub", "mul", "div"):
        monkeypatch.setitem(fpsweep._BINARY, name, F.reference[name])
    monkeypatch.setattr(F, "from_int", F.reference["from_int"])
    result = fpsweep.sweep(avr, op, SLICE_PAIRS, seed=5)
    assert result.mismatches == 0, result.describe()


def test_an_ieee_multiplication_fails_the_sweep(avr: AvrMath, monkeypatch: pytest.MonkeyPatch) -> None:
    """The sweep can fail: with f32.mul correctly rounded (the old port) it finds the
    subnormal products avr-libc rounds as ties."""
    monkeypatch.setattr(F, "mul", lambda a, b: F.f32(a * b))
    monkeypatch.setitem(fpsweep._BINARY, "mul", F.mul)
    result = fpsweep.sweep(avr, "mul", SLICE_PAIRS, seed=3)
    assert result.mismatches > 0
    _cls, a, b, on_avr, ported = result.examples[0]
    assert on_avr != ported and ported == F.bits(F.f32(F.from_bits(a) * F.from_bits(b)))


def test_known_subnormal_products(avr: AvrMath) -> None:
    """avr-facts.md's cases: 5*2**-149 * 0.1f is 0 on the AVR (IEEE: 2**-149),
    25*2**-149 * 0.1f is 2*2**-149 (IEEE: 3*2**-149); and strtod("7.1e-46") is 0."""
    tenth = F.bits(F.f32(0.1))
    on_avr = avr.batch("mul", [5, 25], [tenth, tenth])
    assert [int(w) for w in on_avr] == [0, 2]
    assert F.bits(F.mul(5 * 2.0**-149, F.f32(0.1))) == 0
    assert F.bits(F.mul(25 * 2.0**-149, F.f32(0.1))) == 2
    assert avr.strtod(b"7.1e-46")[0] == 0.0


def test_wcdrive_verify_fp(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """``wcdrive verify --fp N``: a line per operation, exit 0; exit 1 and the
    counterexample when the port's multiplication is the IEEE one."""
    from wcdrive.tools.cli import main

    assert main(["verify", "--fp", "2000", "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    for op in fpsweep.OPERATIONS:
        assert f"{op} pairs=2000 mismatches=0" in out
    assert f"fp pairs={2000 * len(fpsweep.OPERATIONS)} mismatches=0" in out
    monkeypatch.setitem(fpsweep._BINARY, "mul", lambda a, b: F.f32(a * b))
    assert main(["verify", "--fp", "20000", "--jobs", "1"]) == 1   # workers fork: they see the patch
    out = capsys.readouterr().out
    assert "mul pairs=20000 mismatches=0" not in out and "mismatch (" in out


#: The float routines of avr-libc the sweep's operations call (with the internals they
#: share); the entry points a sketch may call are those not starting with __fp_.
SWEPT = {"__addsf3", "__subsf3", "__mulsf3", "__divsf3", "__cmpsf2", "__ltsf2", "__lesf2", "__eqsf2",
         "__nesf2", "__gtsf2", "__gesf2", "__unordsf2", "__fixsfsi", "__fixunssfsi", "__floatsisf",
         "__floatunsisf"}
_FLOAT = re.compile(r"__[a-z]+sf[23]\w*|__fix\w+|__float\w+|__fp_\w+|f(?:abs|min|max|mod)|sqrt|pow|exp|log\w*"
                    r"|(?:a)?(?:sin|cos|tan)h?|atan2|floor|ceil|round|trunc|ldexp|frexp|l?rint|lround")


def _disassembly(elf: Path) -> tuple[set[str], dict[str, list[str]]]:
    """(float routines called anywhere, each routine's instructions without targets)."""
    text = subprocess.run(["avr-objdump", "-d", str(elf)], capture_output=True, text=True,
                          check=True).stdout
    called = {m.split("+")[0] for m in re.findall(r"(?:call|jmp)\s+0x[0-9a-f]+\s+;.*<([^>]+)>", text)}
    bodies: dict[str, list[str]] = {}
    current: list[str] = []
    for line in text.splitlines():
        head = re.match(r"^[0-9a-f]+ <(.+)>:$", line)
        if head:
            current = bodies.setdefault(head.group(1), [])
            continue
        ins = re.match(r"^\s+[0-9a-f]+:\t[0-9a-f ]+\t(\S+)\s*([^;]*)", line)
        if ins:
            op = ins.group(1)
            jumps = op in ("call", "jmp", "rcall", "rjmp") or op.startswith("br")
            current.append(op if jumps else f"{op} {ins.group(2).strip()}")
    return {name for name in called if _FLOAT.fullmatch(name)}, bodies


def test_the_sweep_covers_every_float_routine_the_sketch_calls() -> None:
    """The sketch's float calls are the swept ones (fabs and negation are inline), and
    fpcheck links the very same avr-libc code: a new call (sqrt, say) or another
    avr-libc fails here first."""
    called, sketch = _disassembly(firmware_elf())
    internal = {"__addsf3x", "__mulsf3x", "__divsf3x", "__divsf3_pse", "__mulsf3_pse"}
    assert {name for name in called if not name.startswith("__fp_")} - internal <= SWEPT, called
    in_fpcheck, check = _disassembly(firmware_elf(firmware_dir("fpcheck")))
    assert called <= in_fpcheck
    for name in called:
        assert sketch[name] == check.get(name), f"{name} differs between final_control and fpcheck"
