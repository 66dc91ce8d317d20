"""Checks the Python port against a built firmware, trace by trace.

    python -m wcdrive.verify --traces 200 --seed 1 [--elf PATH] [--duration 5] [--jobs 2]

Runs N random traces (hil.traces) on the firmware in simavr and through the port
(hil.lockstep), and ends with one line:

    traces=N ticks=M mismatches=K

It exits 1 when K > 0, after printing the first mismatch (the tick, the field and
both values in hex) and the trace that produced it.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path


def _check(args: tuple[int, float, str | None]) -> tuple[int, int, int, int, list[str], str]:
    from hil.lockstep import compare, record
    from hil.traces import RandomDraw, generate_trace

    seed, duration, elf = args
    trace = generate_trace(RandomDraw(seed), duration)
    report = compare(record(trace, elf))
    first = [str(m) for m in report.mismatches[:5]]
    return seed, report.ticks, report.fields_compared, len(report.mismatches), first, trace.describe()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wcdrive.verify",
                                     description="Differential check of the port against the firmware.")
    parser.add_argument("--traces", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--elf", type=Path, help="firmware ELF (default: build firmware/final_control)")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds per trace")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    if args.traces < 1 or args.duration <= 0:
        parser.error("--traces must be >= 1 and --duration > 0")

    from hil.build import firmware_elf

    elf = str(args.elf) if args.elf else str(firmware_elf())
    work = [(args.seed * 1_000_003 + k, args.duration, elf) for k in range(args.traces)]
    ticks = fields = mismatches = 0
    first_failure: tuple[int, list[str], str] | None = None
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        for seed, t, f, m, first, described in pool.map(_check, work):
            ticks += t
            fields += f
            mismatches += m
            if m and first_failure is None:
                first_failure = (seed, first, described)
    if first_failure is not None:
        seed, first, described = first_failure
        print(f"first mismatch, trace seed {seed}:")
        for line in first:
            print(f"  {line}")
        print(described)
    from wcdrive.firmware.state import FLOAT_FIELDS, INT_FIELDS

    print(f"compared after each of the firmware's events: {fields} values ({len(FLOAT_FIELDS)}"
          f" controller floats bit for bit, {len(INT_FIELDS)} integers and flags, PWM duty and DIR"
          " of both motors), and the whole TX byte stream of every trace")
    print(f"traces={args.traces} ticks={ticks} mismatches={mismatches}")
    return 1 if mismatches else 0


if __name__ == "__main__":
    sys.exit(main())
