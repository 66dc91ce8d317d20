"""Checks the Python port against a built firmware, trace by trace.

    wcdrive verify --traces 200 --seed 1 [--elf PATH] [--duration 5] [--jobs 2]
                   [--scheduler tcp://HOST:8786]

Runs N random traces (wcdrive.hil.traces) on the firmware in simavr and through the port
(wcdrive.hil.lockstep), and ends with one line:

    traces=N ticks=M mismatches=K

It exits 1 when K > 0, after printing the first mismatch (the tick, the field and
both values in hex) and the trace that produced it.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from pathlib import Path

from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.errors import WcdriveConnectionError
from wcdrive.firmware.state import FLOAT_FIELDS, INT_FIELDS
from wcdrive.hil.lockstep import compare, record
from wcdrive.hil.traces import RandomDraw, generate_trace


def _check(args: tuple[int, float, str | None]) -> tuple[int, int, int, int, list[str], str]:
    seed, duration, elf = args
    trace = generate_trace(RandomDraw(seed), duration)
    report = compare(record(trace, elf))
    first = [str(m) for m in report.mismatches[:5]]
    return seed, report.ticks, report.fields_compared, len(report.mismatches), first, trace.describe()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``wcdrive verify``."""
    parser.add_argument("--traces", type=int, default=20, help="how many random traces (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first trace")
    parser.add_argument("--elf", type=Path, help="firmware ELF (default: build firmware/final_control)")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds per trace")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--scheduler", help="run the traces on this Dask cluster, tcp://HOST:8786 "
                                            "(its workers need wcdrive and the ELF's path)")


@contextlib.contextmanager
def _progress(total: int) -> Iterator[Callable[[], None]]:
    """A ``rich`` bar over the traces on stderr, when it is a terminal."""
    if not sys.stderr.isatty():
        yield lambda: None
        return
    from rich.console import Console
    from rich.progress import Progress

    with Progress(console=Console(stderr=True), transient=True) as bar:
        task = bar.add_task("verify", total=total)
        yield lambda: bar.advance(task)


@contextlib.contextmanager
def _executor(args: argparse.Namespace) -> Iterator[Executor]:
    """Worker processes here, or the Dask cluster at ``--scheduler``."""
    if not getattr(args, "scheduler", None):
        with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            yield pool
        return
    from dask.distributed import Client

    try:
        client = Client(args.scheduler, timeout="10s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise WcdriveConnectionError(f"cannot reach the Dask scheduler at {args.scheduler}: {exc}") from exc
    with client:
        yield client.get_executor(pure=False)


def run(args: argparse.Namespace) -> int:
    """Runs the check; exit status 1 on any mismatch, 2 on bad arguments."""
    if args.traces < 1 or args.duration <= 0:
        print("wcdrive verify: --traces must be >= 1 and --duration > 0", file=sys.stderr)
        return 2
    elf = str(args.elf) if args.elf else str(firmware_elf())
    work = [(args.seed * 1_000_003 + k, args.duration, elf) for k in range(args.traces)]
    ticks = fields = mismatches = 0
    first_failure: tuple[int, list[str], str] | None = None
    with _executor(args) as pool, _progress(len(work)) as advance:
        for seed, t, f, m, first, described in pool.map(_check, work):
            advance()
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
    print(f"compared after each of the firmware's events: {fields} values ({len(FLOAT_FIELDS)}"
          f" controller floats bit for bit, {len(INT_FIELDS)} integers and flags, PWM duty and DIR"
          " of both motors), and the whole TX byte stream of every trace")
    print(f"traces={args.traces} ticks={ticks} mismatches={mismatches}")
    return 1 if mismatches else 0

