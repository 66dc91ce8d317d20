"""Which runtime parameters make the chair oscillate ("Safe parameters"):
the velocity step of tests/firmware/test_gain_safety.py (``step_response``: the parameters set
by framed ``set:`` commands, a CMDVEL step kept fed, the port at the Mega's timing on
the pymunk plant, reversals of the TRUE wheel speed after settling) over a grid of
gains or over random points of a box of ranges.

    python benchmarks/gain_scan.py grid [--kp 0,5,10] [--ki 0.01,5,10] [--kd 0,0.15]
        [--speeds 0.3,1,2,-1,-2] [--accels 5,20] [--jobs N]
    python benchmarks/gain_scan.py random [--examples N] [--seed S] [--same]
        [--range kp=1:10] [--range ki=0.01:10] [--range kd=0:0.2] ... [--jobs N] [--show N]

``grid``: both wheels alike; for each (kp, ki, kd), the worst reversal count over
every step (speed x max_accel), one table of kp (rows) by ki (columns) per kd. A cell
over MAX_REVERSALS breaks the property; ``F`` marks a run that broke it otherwise (a
fault, a refused command, a watchdog stop).

``random``: every parameter drawn independently, uniformly over its range or at one
of its ends (a third of the draws), left and right apart (``--same``: alike). The
ranges are ``wcdrive.firmware.params.PARAMS`` (the spec as it is) unless ``--range``
gives others (``kp``, ``ki``, ``kd`` set both wheels' gains; ``kp_l`` one of them), so
a proposed spec can be tried before it is written. Prints the histogram of the worst
reversal count, what broke the property (a fault by its name, the reversals), the yaw
reached on the straight step (the property does not bound it), the worst count among
the runs that ended without a fault, and the worst runs.

    python benchmarks/gain_scan.py random --range kp=1:10 --range ki=0.01:10 --range kd=0:0.2
"""

from __future__ import annotations

import argparse
import collections
import itertools
import math
import random
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tests.firmware.test_gain_safety import (  # noqa: E402
    MAX_REVERSALS,
    PARAMS,
    SPEED_MAX,
    SPEED_MIN,
    StepRun,
    step_response,
)

Box = dict[str, tuple[float, float]]
Job = tuple[dict[str, float], float]


def floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x]


def run_job(job: Job) -> StepRun:
    return step_response(*job)


def run_all(jobs: list[Job], n_jobs: int) -> list[StepRun]:
    if n_jobs <= 1:
        return [run_job(j) for j in jobs]
    with ProcessPoolExecutor(n_jobs) as pool:
        return list(pool.map(run_job, jobs, chunksize=8))


def score(run: StepRun) -> str:
    """The worst count, ``F`` appended when the run broke the property otherwise."""
    broken = run.failures() and run.worst <= MAX_REVERSALS
    return f"{run.worst}{'F' if broken else ''}"


def cause(run: StepRun) -> str:
    """What broke the property first: a fault (by its EVT:FAULT name), the reversals,
    or another line."""
    if run.fault:
        names = [line[10:] for line in run.bad_lines if line.startswith("EVT:FAULT,")]
        return "fault " + (",".join(names) or f"{run.fault:#x}")
    if run.worst > MAX_REVERSALS:
        return "reversals"
    return "other"


def grid(args: argparse.Namespace) -> None:
    kps, kis, kds = floats(args.kp), floats(args.ki), floats(args.kd)
    steps = list(itertools.product(floats(args.speeds), floats(args.accels)))
    combos = list(itertools.product(kds, kps, kis))
    jobs: list[Job] = []
    for kd, kp, ki in combos:
        gains = {"kp_l": kp, "ki_l": ki, "kd_l": kd, "kp_r": kp, "ki_r": ki, "kd_r": kd}
        jobs += [({**gains, "max_accel": accel}, speed) for speed, accel in steps]
    t0 = time.perf_counter()
    runs = run_all(jobs, args.jobs)
    wall = time.perf_counter() - t0
    cells: dict[tuple[float, float, float], list[StepRun]] = collections.defaultdict(list)
    for (kd, kp, ki), i in zip(combos, range(0, len(runs), len(steps)), strict=True):
        cells[kd, kp, ki] = runs[i:i + len(steps)]
    print(f"worst reversals per wheel over {len(steps)} steps (speeds {args.speeds} m/s x "
          f"max_accel {args.accels} rad/s^2); property: <= {MAX_REVERSALS}")
    for kd in kds:
        print(f"\nkd = {kd:g}: rows kp, columns ki")
        print("   kp\\ki " + "".join(f"{ki:>6g}" for ki in kis))
        for kp in kps:
            row = []
            for ki in kis:
                worst = max(cells[kd, kp, ki], key=lambda r: (r.worst, bool(r.failures())))
                row.append(score(worst))
            print(f"{kp:8g} " + "".join(f"{c:>6}" for c in row))
    print(f"\n{len(runs)} runs in {wall:.1f} s")


def parse_box(ranges: list[str]) -> Box:
    box: Box = {p.name: (float(p.low), float(p.high)) for p in PARAMS}
    for item in ranges:
        name, _, span = item.partition("=")
        low, _, high = span.partition(":")
        names = [f"{name}_l", f"{name}_r"] if name in ("kp", "ki", "kd") else [name]
        for n in names:
            if n not in box:
                raise SystemExit(f"unknown parameter {n}")
            box[n] = (float(low), float(high))
    return box


def draw(rng: random.Random, box: Box, same: bool = False) -> Job:
    values: dict[str, float] = {}
    for p in PARAMS:
        low, high = box[p.name]
        x = rng.random()
        if x < 1 / 6:
            v = low
        elif x < 1 / 3:
            v = high
        else:
            v = rng.uniform(low, high)
        values[p.name] = float(round(v)) if p.integer else v
    if same:
        for gain in ("kp", "ki", "kd"):
            values[f"{gain}_r"] = values[f"{gain}_l"]
    speed = rng.choice((1.0, -1.0)) * round(rng.uniform(SPEED_MIN, SPEED_MAX), 3)
    return values, speed


def random_scan(args: argparse.Namespace) -> None:
    box = parse_box(args.range)
    rng = random.Random(args.seed)
    jobs = [draw(rng, box, args.same) for _ in range(args.examples)]
    t0 = time.perf_counter()
    runs = run_all(jobs, args.jobs)
    wall = time.perf_counter() - t0
    print("box: " + ", ".join(f"{k} {lo:g}..{hi:g}" for k, (lo, hi) in box.items()))
    histogram = collections.Counter(r.worst for r in runs)
    broken = [r for r in runs if r.failures()]
    print(f"{len(runs)} random steps in {wall:.1f} s; worst reversal count per run: "
          + ", ".join(f"{k}: {histogram[k]}" for k in sorted(histogram)))
    print(f"broken: {len(broken)} ({100 * len(broken) / len(runs):.1f} %): "
          + ", ".join(f"{k} {v}" for k, v in collections.Counter(map(cause, broken)).most_common()))
    yaw = [math.degrees(r.yaw) for r in runs]
    print(f"yaw (|heading| reached on a straight step): max {max(yaw):.0f} deg, "
          f"over 45 deg in {sum(y > 45 for y in yaw)}, over 90 deg in {sum(y > 90 for y in yaw)}")
    healthy = [r for r in runs if not r.fault]
    if healthy:
        print(f"without a fault: {len(healthy)} runs, worst reversal count "
              f"{max(r.worst for r in healthy)}, over {MAX_REVERSALS} in "
              f"{sum(r.worst > MAX_REVERSALS for r in healthy)}")
    for r in sorted(runs, key=lambda r: (-r.worst, -bool(r.failures())))[:args.show]:
        print("  " + r.describe())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="mode", required=True)
    g = sub.add_parser("grid")
    g.add_argument("--kp", default="0,2,5,8,10,12,15,20,30,50,100")
    g.add_argument("--ki", default="0.01,1,5,10,15,20,30,50,100")
    g.add_argument("--kd", default="0,0.15,0.3,0.5,1,10")
    g.add_argument("--speeds", default="0.3,1,2,-1,-2")
    g.add_argument("--accels", default="5,20")
    r = sub.add_parser("random")
    r.add_argument("--examples", type=int, default=500)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--range", action="append", default=[], metavar="NAME=LOW:HIGH")
    r.add_argument("--show", type=int, default=10)
    r.add_argument("--same", action="store_true", help="the right wheel's gains = the left's")
    for p in (g, r):
        p.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args(argv)
    grid(args) if args.mode == "grid" else random_scan(args)


if __name__ == "__main__":
    main()
