"""Cycles of an interrupt handler, path by path, from the ELF's disassembly.

``isr_paths(elf, "__vector_5")`` walks every path from the handler's first instruction
to its ``reti`` (conditional branches and skips both ways; handlers have no loops) and
returns each path's cycles on the ATmega2560 (22-bit PC: ``call``/``ret``/``reti`` 5
cycles), plus ``ENTRY_CYCLES``: the chip's interrupt response (5) and the vector's
``jmp`` (3). It is the static half of the firmware's timing budget; the harness charges the same
entry in simulation (``VirtualMega.interrupts_taken``).
"""

from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

#: The interrupt response (5: PC pushed, I cleared) and the vector table's jmp (3).
ENTRY_CYCLES = 5 + 3

_ONE = {"add", "adc", "sub", "sbc", "subi", "sbci", "and", "andi", "or", "ori", "eor", "com",
        "neg", "inc", "dec", "tst", "clr", "ser", "mov", "movw", "ldi", "lsl", "lsr", "rol", "ror",
        "asr", "swap", "cp", "cpc", "cpi", "in", "out", "nop", "sei", "cli", "bst", "bld", "sbr",
        "cbr", "sec", "clc", "sez", "clz", "set", "clt", "wdr"}
_TWO = {"adiw", "sbiw", "lds", "sts", "ld", "st", "ldd", "std", "push", "pop", "rjmp", "cbi",
        "sbi", "mul", "muls", "mulsu", "fmul"}
_FIXED = {"jmp": 3, "lpm": 3, "elpm": 3, "call": 5, "rcall": 4, "icall": 4, "eicall": 4,
          "ret": 5, "reti": 5}
_SKIPS = {"sbrc", "sbrs", "sbic", "sbis", "cpse"}
_LINE = re.compile(r"^\s*([0-9a-f]+):\t((?:[0-9a-f]{2} )+)\s*\t(\S+)\s*([^;]*)")


@dataclass(frozen=True)
class Instruction:
    """One instruction: its byte address, size in 16-bit words, mnemonic and operands."""

    address: int
    words: int
    mnemonic: str
    operands: str


def disassemble(elf: str | Path) -> dict[int, Instruction]:
    """Every instruction of the ELF by byte address (avr-objdump -d)."""
    out = subprocess.run(["avr-objdump", "-d", str(elf)], capture_output=True, text=True,
                         check=True).stdout
    code: dict[int, Instruction] = {}
    for line in out.splitlines():
        m = _LINE.match(line)
        if m:
            size = len(m[2].split())
            code[int(m[1], 16)] = Instruction(int(m[1], 16), size // 2, m[3], m[4].strip())
    return code


def symbol_address(elf: str | Path, name: str) -> int:
    """A function's byte address (avr-nm)."""
    out = subprocess.run(["avr-nm", str(elf)], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2] == name:
            return int(parts[0], 16)
    raise KeyError(f"no symbol {name} in {elf}")


def _target(ins: Instruction) -> int:
    """A branch's or jump's destination (avr-objdump prints it after ';')."""
    m = re.search(r"\.([+-]\d+)", ins.operands)
    if m:                              # relative: .+N from the next instruction
        return ins.address + 2 + int(m[1])
    return int(ins.operands.split(",")[-1].strip(), 0)


def isr_paths(elf: str | Path, symbol: str, limit: int = 10_000) -> list[tuple[int, list[int]]]:
    """Every path through the handler ``symbol`` to a ``reti``: (cycles including
    ``ENTRY_CYCLES``, the addresses on the path). Raises on a call or a loop (a
    handler this budget applies to has neither)."""
    code = disassemble(elf)
    start = symbol_address(elf, symbol)
    paths: list[tuple[int, list[int]]] = []
    stack: list[tuple[int, int, list[int]]] = [(start, ENTRY_CYCLES, [])]
    while stack:
        pc, cycles, path = stack.pop()
        if pc in path:
            raise ValueError(f"{symbol}: a loop at {pc:#x}")
        ins = code[pc]
        path = [*path, pc]
        op = ins.mnemonic
        nxt = pc + 2 * ins.words
        if op == "reti":
            paths.append((cycles + 5, path))
        elif op in _ONE:
            stack.append((nxt, cycles + 1, path))
        elif op in _TWO and op != "rjmp":
            stack.append((nxt, cycles + 2, path))
        elif op == "rjmp":
            stack.append((_target(ins), cycles + 2, path))
        elif op == "jmp":
            stack.append((_target(ins), cycles + 3, path))
        elif op.startswith("br"):
            stack.append((nxt, cycles + 1, path))
            stack.append((_target(ins), cycles + 2, path))
        elif op in _SKIPS:
            after = code[nxt]
            stack.append((nxt, cycles + 1, path))
            stack.append((nxt + 2 * after.words, cycles + 1 + after.words, path))
        elif op in _FIXED:
            raise ValueError(f"{symbol}: {op} at {pc:#x}: not a leaf handler")
        else:
            raise ValueError(f"{symbol}: no cycle count for {op} at {pc:#x}")
        if len(paths) > limit:
            raise ValueError(f"{symbol}: more than {limit} paths")
    return sorted(paths, key=lambda p: p[0])
