"""Checks the Python port against a built firmware, trace by trace.

    wcdrive verify --traces 200 --seed 1 [--elf PATH] [--duration 5] [--jobs 2]
                   [--scheduler tcp://HOST:8786]

Runs N random traces (wcdrive.hil.traces) on the firmware in simavr and through the port
(wcdrive.hil.lockstep), and ends with one line:

    traces=N ticks=M mismatches=K lost_bytes=L stalls=S rx_lost=R

K counts every difference, L the bytes the host sent that the firmware lost without
seeing the loss, S the stalls of the control tick (a tick more than 10 ms late, or a
``millis()`` that does not follow the clock); L and S are also among the K. R counts
the received bytes lost and accounted for on both sides (a full RX ring, an overrun:
``ERR:overrun``); it is a figure, not a failure. It exits 1 when K, L or S > 0, after
printing the first mismatch (the tick, the field and both values in hex) and the trace
that produced it.

    wcdrive verify --fp N [--seed S] [--jobs 2]

instead runs the binary32 sweep (wcdrive.hil.fpsweep): N operand pairs for each float
operation the sketch calls, on the AVR (firmware/fpcheck, built with the installed
toolchain) against the port's wcdrive.avr.f32, and prints one line per operation,
``op pairs=P mismatches=K``, then ``fp pairs=P mismatches=K``; exit status 1 on any
mismatch. For users who change the toolchain (avr-gcc, avr-libc).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from wcdrive.boards.simavr.build import firmware_elf
from wcdrive.errors import WcdriveConnectionError
from wcdrive.firmware.state import FLOAT_FIELDS, INT_FIELDS
from wcdrive.hil.fpcheck import AvrMath
from wcdrive.hil.fpsweep import OPERATIONS, SweepResult, sweep
from wcdrive.hil.lockstep import compare, record
from wcdrive.hil.traces import RandomDraw, generate_trace


@dataclass
class _Result:
    seed: int
    ticks: int
    fields: int
    mismatches: int
    lost_bytes: int
    stalls: int
    rx_lost: int
    first: list[str]
    trace: str


def _check(args: tuple[int, float, str | None]) -> _Result:
    seed, duration, elf = args
    trace = generate_trace(RandomDraw(seed), duration)
    report = compare(record(trace, elf))
    first = [str(m) for m in report.mismatches[:5]]
    return _Result(seed, report.ticks, report.fields_compared, len(report.mismatches),
                   report.lost_bytes, report.stalls, report.rx_lost, first, trace.describe())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``wcdrive verify``."""
    parser.add_argument("--traces", type=int, default=20, help="how many random traces (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first trace")
    parser.add_argument("--elf", type=Path, help="firmware ELF (default: build firmware/final_control)")
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds per trace")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--fp", type=int, metavar="N",
                        help="instead: the binary32 sweep, N pairs per float operation (see above)")
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


def _sweep(job: tuple[str, int, int]) -> SweepResult:
    op, n, seed = job
    avr = AvrMath()
    try:
        return sweep(avr, op, n, seed)
    finally:
        avr.close()


def run_fp(pairs: int, seed: int, jobs: int) -> int:
    """The binary32 sweep; exit status 1 on any mismatch."""
    count = mismatches = 0
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool:
        for result in pool.map(_sweep, [(op, pairs, seed) for op in OPERATIONS]):
            count += result.count
            mismatches += result.mismatches
            print(f"{result.op} pairs={result.count} mismatches={result.mismatches}"
                  + (f" not_ieee={result.not_ieee}" if result.op in ("add", "sub", "mul", "div") else ""),
                  flush=True)
            if result.mismatches:
                print(result.describe(), flush=True)
    print(f"fp pairs={count} mismatches={mismatches}")
    return 1 if mismatches else 0


def run(args: argparse.Namespace) -> int:
    """Runs the check; exit status 1 on any mismatch, 2 on bad arguments."""
    if args.fp is not None:
        if args.fp < 1:
            print("wcdrive verify: --fp must be >= 1", file=sys.stderr)
            return 2
        return run_fp(args.fp, args.seed, args.jobs)
    if args.traces < 1 or args.duration <= 0:
        print("wcdrive verify: --traces must be >= 1 and --duration > 0", file=sys.stderr)
        return 2
    elf = str(args.elf) if args.elf else str(firmware_elf())
    work = [(args.seed * 1_000_003 + k, args.duration, elf) for k in range(args.traces)]
    ticks = fields = mismatches = lost = stalls = rx_lost = 0
    first_failure: _Result | None = None
    with _executor(args) as pool, _progress(len(work)) as advance:
        for r in pool.map(_check, work):
            advance()
            ticks += r.ticks
            fields += r.fields
            mismatches += r.mismatches
            lost += r.lost_bytes
            stalls += r.stalls
            rx_lost += r.rx_lost
            if r.mismatches and first_failure is None:
                first_failure = r
    if first_failure is not None:
        print(f"first mismatch, trace seed {first_failure.seed}:")
        for line in first_failure.first:
            print(f"  {line}")
        print(first_failure.trace)
    print(f"compared after each of the firmware's events: {fields} values ({len(FLOAT_FIELDS)}"
          f" controller floats bit for bit, {len(INT_FIELDS)} integers and flags, PWM duty and DIR"
          " of both motors), the whole TX byte stream, every byte sent against what the"
          " firmware received, and the tick's regularity, of every trace")
    print(f"traces={args.traces} ticks={ticks} mismatches={mismatches} lost_bytes={lost} "
          f"stalls={stalls} rx_lost={rx_lost}")
    return 1 if mismatches or lost or stalls else 0
