"""Single floating-point and formatting operations run on the simulated AVR.

``AvrMath`` drives firmware/fpcheck: it writes operands into the sketch's globals,
lets ``loop()`` run one operation and reads the result. It is the ground truth the
port's binary32 helpers, ``strtod`` and ``printFloat`` are checked against.
"""

from __future__ import annotations

from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.boards.simavr.virtual_mega import VirtualMega
from wcdrive.resources import firmware_dir

OPS = {"div": 1, "mul": 2, "add": 3, "sub": 4, "strtod": 5, "print": 6, "from_int": 7, "to_int": 8}


class AvrMath:
    """The fpcheck sketch (built if needed) on a ``VirtualMega``, one operation a call."""

    def __init__(self) -> None:
        self.mega = VirtualMega(firmware_elf(firmware_dir("fpcheck")))
        self.mega.break_on("doneOp")
        self.mega.run_for(0.001)

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
