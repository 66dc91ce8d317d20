"""Single floating-point and formatting operations run on the simulated AVR.

``AvrMath`` drives firmware/fpcheck: it writes operands into the sketch's globals,
lets ``loop()`` run one operation and reads the result. It is the ground truth the
port's binary32 helpers, ``strtod`` and ``printFloat`` are checked against.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wcdrive._util.resources import firmware_dir
from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.boards.simavr.virtual_mega import VirtualMega

OPS = {"div": 1, "mul": 2, "add": 3, "sub": 4, "strtod": 5, "print": 6, "from_int": 7, "to_int": 8}

#: Operations of ``AvrMath.batch``: the name and the sketch's op code (ORed with 0x80).
#: Operands and results are raw 32-bit words: binary32 encodings, except the integer
#: operand of "floatsisf"/"floatunsisf" and the results of "fixsfsi"/"fixunssfsi"
#: (int32/uint32), and of "cmp" (bit 0..6: < <= > >= == != unordered).
BATCH_OPS = {"div": 1, "mul": 2, "add": 3, "sub": 4, "cmp": 9, "fixsfsi": 10,
             "fixunssfsi": 11, "floatsisf": 12, "floatunsisf": 13}
BATCH = 256

class AvrMath:
    """The fpcheck sketch (built if needed) on a ``VirtualMega``, one operation a call."""

    def __init__(self) -> None:
        self.mega = VirtualMega(firmware_elf(firmware_dir("fpcheck")))
        self.mega.break_on("doneOp")
        self.mega.run_for(0.005)   # past the C start-up, which clears .bss (the batch arrays)

    def close(self) -> None:
        """Frees the virtual Mega."""
        self.mega.close()

    def _run(self, op: str) -> None:
        self.mega.write("op", OPS[op], "B")
        if not self.mega.run_to_break(self.mega.cycle + 4_000_000):
            raise RuntimeError(f"fpcheck did not finish {op}")

    def binary(self, op: str, a: float, b: float) -> float:
        """``a <op> b`` in binary32 on the AVR; ``op`` is "div", "mul", "add" or "sub"."""
        self.mega.write("argA", a, "f")
        self.mega.write("argB", b, "f")
        self._run(op)
        return self.mega.read("result", "f")

    def strtod(self, text: bytes) -> tuple[float, int]:
        """avr-libc's ``strtod`` of ``text``: (value, bytes consumed)."""
        if len(text) >= 80 or b"\0" in text:
            raise ValueError("text must be shorter than 80 bytes, without NUL")
        self.mega.write_raw("text", text + b"\0")
        self._run("strtod")
        return float(self.mega.read("result", "f")), int(self.mega.read("consumed", "h"))

    def print_float(self, x: float, digits: int) -> bytes:
        """What ``Print::print(x, digits)`` prints on the AVR."""
        self.mega.write("argA", x, "f")
        self.mega.write("argDigits", digits, "B")
        self._run("print")
        n = int(self.mega.read("printedLen", "B"))
        return self.mega.read_raw("printed")[:n]

    def from_int(self, n: int) -> float:
        """``(float)n`` of a 32-bit integer on the AVR."""
        self.mega.write("argInt", n, "i")
        self._run("from_int")
        return self.mega.read("result", "f")

    def batch(self, op: str, a: Sequence[int] | np.ndarray, b: Sequence[int] | np.ndarray | None = None,
              ) -> np.ndarray:
        """Runs ``op`` (a key of ``BATCH_OPS``) on the AVR for every pair of 32-bit words
        ``a[i]``, ``b[i]`` (``b`` unused by the conversions), ``BATCH`` pairs per simavr
        run; returns the result words as a uint32 array."""
        code = BATCH_OPS[op] | 0x80
        wa = np.asarray(a, dtype=np.uint32)
        wb = np.zeros_like(wa) if b is None else np.asarray(b, dtype=np.uint32)
        if wa.shape != wb.shape or wa.ndim != 1:
            raise ValueError("a and b must be 1-d and of one length")
        out = np.empty_like(wa)
        mega = self.mega
        for start in range(0, len(wa), BATCH):
            n = min(BATCH, len(wa) - start)
            mega.write_raw("batchA", wa[start:start + n].astype("<u4").tobytes())
            mega.write_raw("batchB", wb[start:start + n].astype("<u4").tobytes())
            mega.write("batchN", n, "H")
            mega.write("op", code, "B")
            if not mega.run_to_break(mega.cycle + 2_000 * n + 100_000):
                raise RuntimeError(f"fpcheck did not finish a batch of {op}")
            out[start:start + n] = np.frombuffer(mega.read_raw("batchR")[:4 * n], dtype="<u4")
        return out
