"""A whole run (``run``) and the command line (``main``)."""

from __future__ import annotations

import argparse
import random
import sys
import time

from .common import FULL, QUICK, ElfPath
from .r1 import firmware_r1, port_r1
from .r2 import firmware_r2, legacy_rates, port_r2
from .r3 import firmware_r3
from .report import Results, markdown, problems

# ---- the whole run -----------------------------------------------------------------
#: The command line's description: the first paragraph of the package's docstring.
DESCRIPTION = ("Reliability benchmark for protocol v3: the Python port and the compiled firmware "
               "in simavr take the same hostile input, and nothing but a valid command moves the "
               "chair. docs/benchmarks.md (\"Reliability (protocol v3)\") keeps the figures.")


def run(counts: dict[str, int], seed: int = 1, simavr: bool = True, elf: ElfPath = None,
        log: bool = False, r3_pace: float = 1.0) -> Results:
    """Every test with these counts (keys of ``FULL``); R3's board runs at ``r3_pace``
    times real time."""
    res = Results(seed, dict(counts))

    def timed(name: str, fn, *args):
        t0 = time.perf_counter()
        value = fn(*args)
        res.wall[name] = time.perf_counter() - t0
        if log:
            print(f"  {name}: {res.wall[name]:.1f} s", file=sys.stderr, flush=True)
        return value

    lines = counts["port_lines"]
    legacy_lines = lines // 5
    res.r1_port["strict"] = timed("R1 port, strict", port_r1, lines - legacy_lines,
                                  random.Random(seed * 1000 + 1), True)
    res.r1_port["legacy"] = timed("R1 port, legacy", port_r1, legacy_lines,
                                  random.Random(seed * 1000 + 2), False)
    res.r2_port = timed("R2 port", port_r2, counts["port_frames"], random.Random(seed * 1000 + 3))
    res.legacy = timed("v1/v2 comparison", legacy_rates, counts["legacy_frames"],
                       random.Random(seed * 1000 + 4))
    if simavr:
        if elf is None:
            from wcdrive.boards.simavr.build import firmware_elf

            elf = firmware_elf()
        res.r1_firmware = timed("R1 firmware", firmware_r1, counts["firmware_lines"],
                                random.Random(seed * 1000 + 5), elf)
        res.r2_firmware = timed("R2 firmware", firmware_r2, counts["firmware_frames"],
                                random.Random(seed * 1000 + 6), elf)
        if counts.get("r3_trials", 0) > 0:
            res.r3 = timed("R3 firmware", firmware_r3, counts["r3_trials"],
                           random.Random(seed * 1000 + 7), elf, log, r3_pace)
    return res




def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=DESCRIPTION)
    parser.add_argument("--quick", action="store_true", help="small counts (seconds)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--no-simavr", action="store_true", help="the port only")
    for key in FULL:
        parser.add_argument("--" + key.replace("_", "-"), type=int, default=None)
    parser.add_argument("--r3-pace", type=float, default=1.0,
                        help="R3's board (and host clock) at this times real time (a loaded machine: 0.5)")
    args = parser.parse_args(argv)
    counts = dict(QUICK if args.quick else FULL)
    for key in FULL:
        value = getattr(args, key)
        if value is not None:
            counts[key] = value
    t0 = time.perf_counter()
    res = run(counts, args.seed, simavr=not args.no_simavr, log=True, r3_pace=args.r3_pace)
    print(markdown(res))
    found = problems(res)
    print()
    print("Problems:\n" + "\n".join(found) if found else "No problem found.")
    print(f"Wall time {time.perf_counter() - t0:.1f} s.")
    return 1 if found else 0

