"""The binary32 sweep: every float operation the sketch calls, run on the AVR in batches
(``AvrMath.batch``) and through the port's ``wcdrive.avr.f32``, bit for bit.

The operations are those ``final_control.elf`` calls (its symbol table and call sites):
``__addsf3``, ``__subsf3``, ``__mulsf3``, ``__divsf3``, the comparisons (``__cmpsf2`` and
its aliases ``__ltsf2 __lesf2 __eqsf2 __nesf2``, ``__gtsf2``/``__gesf2``, ``__unordsf2``),
``__fixsfsi``, ``__fixunssfsi``, ``__floatsisf`` and ``__floatunsisf``. ``fabs`` and
negation are inline sign-bit operations, ``constrain`` is comparisons.

Each operation's pairs mix classes (``pairs``): uniform random words (every class,
NaN and inf included), the cross product of special values (signed zeros, subnormal
and normal bounds, inf, NaNs with payloads, integer-conversion bounds, the sketch's
constants), and targeted sets per operation: subnormal products and quotients, the
constructed near-ties whose discarded bits decide the rounding, exponent differences
around the guard bit for + and -, overflow, equal and adjacent pairs for the
comparisons, values around 2**31 and 2**32 for the conversions, integers next to
rounding ties for int to float.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wcdrive.avr import f32 as F
from wcdrive.firmware import constants as C
from wcdrive.hil.fpcheck import BATCH_OPS, AvrMath

OPERATIONS = tuple(BATCH_OPS)
U32 = np.uint32

#: Special binary32 words: zeros, subnormal and normal bounds, inf, NaNs, ones, and the
#: integer conversions' bounds (2**31, 2**32 and their neighbours).
SPECIAL_WORDS = (
    0x00000000, 0x00000001, 0x00000002, 0x00000003, 0x00400000, 0x007FFFFF, 0x00800000,
    0x00800001, 0x00FFFFFF, 0x01000000, 0x7F7FFFFF, 0x7F7FFFFE, 0x7F000000, 0x7F800000,
    0x7FC00000, 0x7F800001, 0x7FFFFFFF, 0x7FC0ABCD, 0x3F800000, 0x3F800001, 0x3F7FFFFF,
    0x3F000000, 0x3FC00000, 0x40000000, 0x33800000, 0x33800001, 0x34000000, 0x4B000000,
    0x4B7FFFFF, 0x4B800000, 0x4EFFFFFF, 0x4F000000, 0x4F000001, 0x4F7FFFFF, 0x4F800000,
    0x1F800000, 0x20000000, 0x5F800000, 0x5F000000,
)


def _special_words() -> np.ndarray:
    consts = [F.bits(v) for v in vars(C).values() if isinstance(v, float) and math.isfinite(v)]
    base = np.array(sorted(set(SPECIAL_WORDS) | set(consts)), dtype=np.uint64)
    return np.concatenate([base, base | 0x80000000]).astype(U32)


def _random_words(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.integers(0, 2**32, n, dtype=np.uint64).astype(U32)


def _compose(rng: np.random.Generator, exponent: np.ndarray, mantissa: np.ndarray | None = None,
             sign: bool = True) -> np.ndarray:
    """Words from biased exponent fields (clipped to 0..254) and 23-bit mantissas."""
    n = len(exponent)
    if mantissa is None:
        mantissa = rng.integers(0, 2**23, n, dtype=np.uint64)
    e = np.clip(exponent, 0, 254).astype(np.uint64)
    word = (e << np.uint64(23)) | (mantissa.astype(np.uint64) & np.uint64(0x7FFFFF))
    if sign:
        word |= rng.integers(0, 2, n, dtype=np.uint64) << np.uint64(31)
    return word.astype(U32)


def _fields(words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w = words.astype(np.int64)
    return (w >> 23) & 0xFF, w & 0x7FFFFF


def _mul_near_ties(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Products that __mulsf3 shifts right by 1..24 bits, built so that the bits left
    after the shift sit at, or one unit beside, a rounding tie (guard bit set, the rest
    zero) while the bits shifted out are not zero: where avr-libc and IEEE part."""
    a = np.empty(n, dtype=U32)
    b = np.empty(n, dtype=U32)
    shifts = rng.integers(1, 25, n)
    mbs = rng.integers(2**23, 2**24, n)
    mas = rng.integers(2**23, 2**24, n)
    deltas = rng.integers(-1, 2, n)
    ebs = rng.integers(1, 100, n)
    for i in range(n):
        sh, mb = int(shifts[i]), int(mbs[i])
        x = (int(mas[i]) * mb) >> sh
        x = (x & ~0xFFFFFF) | 0x800000
        x = max(x + int(deltas[i]), 1)
        ma = -(-(x << sh) // mb)               # ceil: the product just above x << sh
        if not 2**23 <= ma < 2**24:
            ma = int(mas[i])
        eb = int(ebs[i])
        ea = 127 - sh - eb                     # exponent sum: e' = -sh
        if ea < 1:
            ea, eb = 1, 126 - sh
        sign = int(rng.integers(0, 4))
        a[i] = ((sign & 1) << 31) | (ea << 23) | (ma & 0x7FFFFF)
        b[i] = ((sign >> 1) << 31) | (eb << 23) | (mb & 0x7FFFFF)
    return a, b


def _div_near_ties(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Quotients exactly on, or one ulp of the dividend beside, a subnormal rounding
    tie: a = (2m+1) * c * 2**(k-150), b = c * 2**k."""
    a = np.empty(n, dtype=U32)
    b = np.empty(n, dtype=U32)
    for i in range(n):
        c = int(rng.integers(1, 2**10)) | 1
        m = int(rng.integers(0, 2**23 // c)) if c < 2**23 else 0
        k = int(rng.integers(0, 100))
        av = F.f32((2 * m + 1) * c * 2.0 ** (k - 150))
        bv = F.f32(c * 2.0**k)
        wa = F.bits(av) + int(rng.integers(-1, 2))
        a[i] = wa & 0x7FFFFFFF
        b[i] = F.bits(bv)
    return a, b


def _targeted(op: str, rng: np.random.Generator, n: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The operation's own classes, about n pairs in all."""
    k = max(1, n // 4)
    r = rng.integers
    consts = np.array([F.bits(v) for v in vars(C).values() if isinstance(v, float)], dtype=U32)
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if op == "mul":
        ea = r(0, 127, k)
        out["subnormal product"] = (_compose(rng, ea), _compose(rng, 127 - ea + r(-26, 3, k)))
        small = r(1, 4096, k).astype(U32)
        cb = np.where(r(0, 2, k) == 1, consts[r(0, len(consts), k)], _compose(rng, r(100, 150, k)))
        out["k*2^-149 x constant"] = (small, cb)
        out["near tie, shifted"] = _mul_near_ties(rng, k)
        e = r(0, 255, k)
        out["overflow / exponent bounds"] = (_compose(rng, e), _compose(rng, 254 + 127 - e + r(-3, 3, k)))
    elif op == "div":
        ea = r(0, 40, k)
        out["subnormal quotient"] = (_compose(rng, ea), _compose(rng, ea + 127 + r(-2, 26, k)))
        small = r(1, 2**16, k).astype(U32)
        out["k*2^-149 / constant"] = (small, consts[r(0, len(consts), k)])
        out["near tie"] = _div_near_ties(rng, k)
        e = r(0, 255, k)
        out["overflow / exponent bounds"] = (_compose(rng, e), _compose(rng, e - 127 + r(-3, 3, k)))
    elif op in ("add", "sub"):
        a = _compose(rng, r(1, 255, k))
        ea, _ = _fields(a)
        out["exponent difference -30..30"] = (a, _compose(rng, ea + r(-30, 31, k)))
        mant = np.choose(r(0, 4, k), [np.zeros(k, np.int64), np.ones(k, np.int64),
                                      np.full(k, 0x7FFFFF, np.int64), r(0, 2**23, k)])
        a2 = _compose(rng, r(30, 255, k))
        ea2, _ = _fields(a2)
        out["near tie (guard bit)"] = (a2, _compose(rng, ea2 - r(22, 27, k), mant))
        out["subnormal / smallest normal"] = (_compose(rng, r(0, 3, k)), _compose(rng, r(0, 3, k)))
        e = r(250, 255, k)
        out["overflow"] = (_compose(rng, e, sign=False), _compose(rng, e - r(0, 3, k), sign=False))
    elif op == "cmp":
        a = _random_words(rng, k)
        out["equal"] = (a, a.copy())
        out["adjacent"] = (a, (a.astype(np.int64) + r(-2, 3, k)).astype(U32))
        out["negated"] = (a, a ^ U32(0x80000000))
        tiny = (_compose(rng, r(0, 2, k), r(0, 4, k)), _compose(rng, r(0, 2, k), r(0, 4, k)))
        out["subnormal and zero"] = tiny
    elif op in ("fixsfsi", "fixunssfsi"):
        zero = np.zeros(k, dtype=U32)
        out["0.5 .. 2^33"] = (_compose(rng, r(126, 161, k)), zero)
        near = _compose(rng, r(156, 161, k), np.where(r(0, 2, k) == 1, r(0, 4, k), 2**23 - r(1, 5, k)))
        out["around 2^31, 2^32"] = (near, zero)
        out["below 1, subnormal"] = (_compose(rng, r(0, 127, k)), zero)
        ints = rng.integers(-(2**33), 2**33, k)
        out["integer values"] = (np.array([F.bits(F.from_int(int(v))) for v in ints], dtype=U32), zero)
    elif op in ("floatsisf", "floatunsisf"):
        zero = np.zeros(k, dtype=U32)
        s = r(1, 9, k)
        high = r(0, 2**32, k, dtype=np.uint64) >> s.astype(np.uint64)
        tie = (high << s.astype(np.uint64)) | (np.uint64(1) << (s - 1).astype(np.uint64))
        beside = (tie.astype(np.int64) + r(-1, 2, k)).astype(np.uint64)
        out["near tie"] = ((beside & np.uint64(0xFFFFFFFF)).astype(U32), zero)
        little = r(-(2**25), 2**25, k)
        out["|n| < 2^25"] = ((little & 0xFFFFFFFF).astype(U32), zero)
        bounds = np.array([0, 1, 0xFFFFFFFF, 0x7FFFFFFF, 0x80000000, 0x80000001, 2**24 - 1, 2**24,
                           2**24 + 1, 2**25 + 1, 2**31 - 64, 2**31 - 65, 2**32 - 128, 2**32 - 129],
                          dtype=U32)
        out["bounds"] = (np.resize(bounds, k), zero)
    return out


def pairs(op: str, n: int, seed: int = 0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """About ``n`` operand pairs (32-bit words) for ``op``, by class; the same seed gives
    the same pairs."""
    if op not in BATCH_OPS:
        raise ValueError(f"unknown operation {op!r}; one of {', '.join(OPERATIONS)}")
    rng = np.random.default_rng([seed, OPERATIONS.index(op)])
    specials = _special_words()
    sa, sb = np.meshgrid(specials, specials)
    classes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    cross = (sa.ravel(), sb.ravel())
    take = min(len(cross[0]), max(1, n // 10))
    classes["specials x specials"] = (cross[0][:take], cross[1][:take])
    left = n - take
    targeted = _targeted(op, rng, left * 7 // 10)
    uniform = max(0, left - sum(len(a) for a, _ in targeted.values()))
    classes["uniform words"] = (_random_words(rng, uniform), _random_words(rng, uniform))
    classes.update(targeted)
    return classes


def _floats(words: np.ndarray) -> list[float]:
    with np.errstate(invalid="ignore"):     # signalling NaNs become quiet: low bits kept
        return np.asarray(words, dtype="<u4").view("<f4").astype(np.float64).tolist()


def ieee(op: str, a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """IEEE 754 binary32 (numpy, round to nearest even) for + - * /, else None."""
    ufunc = {"add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide}.get(op)
    if ufunc is None:
        return None
    fa = np.asarray(a, dtype="<u4").view("<f4")
    fb = np.asarray(b, dtype="<u4").view("<f4")
    with np.errstate(all="ignore"):
        return np.asarray(ufunc(fa, fb), dtype=np.float32).view(np.uint32)


def _words_of(values: list[float]) -> np.ndarray:
    return np.array(values, dtype=np.float64).astype(np.float32).view(np.uint32)


def _cmp(a: float, b: float) -> int:
    return ((a < b) | (a <= b) << 1 | (a > b) << 2 | (a >= b) << 3 | (a == b) << 4 | (a != b) << 5
            | (a != a or b != b) << 6)


_BINARY: dict[str, Callable[[float, float], float]] = {
    "add": F.add, "sub": F.sub, "mul": F.mul, "div": F.div}


def port(op: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The port's result words for the pairs: ``wcdrive.avr.f32`` for the arithmetic and
    conversions, Python's comparison operators (what the port uses) for ``cmp``."""
    if op in _BINARY:
        fn = _BINARY[op]
        return _words_of(list(map(fn, _floats(a), _floats(b))))
    if op == "cmp":
        return np.array(list(map(_cmp, _floats(a), _floats(b))), dtype=U32)
    if op == "fixsfsi":
        return np.array([F.to_int_trunc(x) & 0xFFFFFFFF for x in _floats(a)], dtype=U32)
    if op == "fixunssfsi":
        return np.array([F.to_u32(x) for x in _floats(a)], dtype=U32)
    if op == "floatsisf":
        return _words_of([F.from_int(n) for n in np.asarray(a, dtype=U32).view(np.int32).tolist()])
    if op == "floatunsisf":
        return _words_of([F.from_int(n) for n in np.asarray(a, dtype=U32).tolist()])
    raise ValueError(f"unknown operation {op!r}")


@dataclass
class SweepResult:
    """One operation's sweep: pair count and mismatches, per class and in all."""

    op: str
    count: int = 0
    mismatches: int = 0
    by_class: dict[str, tuple[int, int]] = field(default_factory=dict)
    examples: list[tuple[str, int, int, int, int]] = field(default_factory=list)  # class, a, b, avr, port
    #: pairs whose AVR result is a number other than IEEE's correctly rounded one
    not_ieee: int = 0
    not_ieee_examples: list[tuple[int, int, int, int]] = field(default_factory=list)  # a, b, avr, ieee

    def describe(self) -> str:
        """Counts per class, the mismatches kept, and the AVR's departures from IEEE."""
        lines = [f"{self.op}: pairs={self.count} mismatches={self.mismatches}"]
        for cls, (count, bad) in self.by_class.items():
            lines.append(f"  {cls}: {count} pairs, {bad} mismatches")
        for cls, a, b, avr, ported in self.examples:
            lines.append(f"  mismatch ({cls}): a=0x{a:08X} b=0x{b:08X} avr=0x{avr:08X} port=0x{ported:08X}")
        if self.op in _BINARY:
            lines.append(f"  AVR result not IEEE's (NaN payloads aside): {self.not_ieee}")
        for a, b, avr, correct in self.not_ieee_examples:
            lines.append(f"    a=0x{a:08X} b=0x{b:08X} avr=0x{avr:08X} ieee=0x{correct:08X}")
        return "\n".join(lines)


def check(avr: AvrMath, op: str, a: np.ndarray, b: np.ndarray, result: SweepResult,
          cls: str = "given", keep: int = 5) -> None:
    """Runs the pairs on the AVR and through the port and adds the comparison to ``result``."""
    a = np.asarray(a, dtype=U32)
    b = np.asarray(b, dtype=U32)
    on_avr = avr.batch(op, a, b)
    ported = port(op, a, b)
    bad = np.nonzero(on_avr != ported)[0]
    count, before = result.by_class.get(cls, (0, 0))
    result.by_class[cls] = (count + len(a), before + len(bad))
    result.count += len(a)
    result.mismatches += len(bad)
    for i in bad[: max(0, keep - len(result.examples))]:
        result.examples.append((cls, int(a[i]), int(b[i]), int(on_avr[i]), int(ported[i])))
    correct = ieee(op, a, b)
    if correct is not None:
        nan = ((on_avr & 0x7F800000) == 0x7F800000) & ((on_avr & 0x7FFFFF) != 0)
        off = np.nonzero((on_avr != correct) & ~nan)[0]
        result.not_ieee += len(off)
        for i in off[: max(0, keep - len(result.not_ieee_examples))]:
            result.not_ieee_examples.append((int(a[i]), int(b[i]), int(on_avr[i]), int(correct[i])))


def sweep(avr: AvrMath, op: str, n: int, seed: int = 0, chunk: int = 65_536) -> SweepResult:
    """About ``n`` pairs of ``op`` (see ``pairs``) on the AVR against the port."""
    result = SweepResult(op)
    for cls, (a, b) in pairs(op, n, seed).items():
        for start in range(0, len(a), chunk):
            check(avr, op, a[start:start + chunk], b[start:start + chunk], result, cls)
    return result
