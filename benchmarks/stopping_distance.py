"""The stopping-distance table (docs/safety.md): how far the chair travels,
and how long it takes to stand still, after the host's last byte.

    python benchmarks/stopping_distance.py [--backend port|simavr|both]
        [--speeds 0.5 1.0 1.95 2.68] [--watchdog 100 500 1000] [--elf PATH] [--json]

For each start speed and each ``watchdog_ms`` the host sets ``watchdog_ms`` (and
nothing else), drives straight at that speed until the chair runs steadily, then goes
silent (a ``silence`` segment). From the moment the board received its last byte
(``fault_at_s`` of ``wcdrive sim``) the plant's ground truth gives the distance
travelled (``travel_after_fault_m``) and the time until the chair's speed stays below
0.01 m/s (``standstill_after_fault_s``). The bound is the issue's goal
(``wcdrive.sim.safety.stopping_bound``): the true speed at the last byte over the
watchdog time and its latency (up to two 50 ms ticks), plus the braking distance at
``estop_decel`` or at the hardest the motors can brake (``ChairParams.max_braking``,
1.12 m/s^2), whichever is gentler, plus 0.1 m.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass

from wcdrive.protocol.spec import real
from wcdrive.sim import runner, safety
from wcdrive.sim.scenario import Scenario, Segment

SPEEDS = (0.5, 1.0, 1.95, 2.68)
WATCHDOGS = (100, 500, 1000)
#: rad/s^2: the firmware's normal setpoint ramp, to size the drive segment.
MAX_ACCEL = real("MAX_ACCEL")
#: s the chair drives at speed after the ramp, and s of silence after it.
STEADY_S = 2.5
SILENCE_S = 5.0


@dataclass
class Row:
    """One cell of the table: the backend, the commanded speed (m/s), ``watchdog_ms``,
    the true speed at the last byte (m/s), the distance (m) and time to standstill (s)
    after it (None: still moving at the end), the bound (m) and the wall time (s)."""

    backend: str
    speed: float
    watchdog_ms: int
    speed_at_last_byte: float
    distance_m: float
    standstill_s: float | None
    bound_m: float
    wall_s: float

    @property
    def within(self) -> bool:
        """Whether the chair stopped within the bound."""
        return self.standstill_s is not None and self.distance_m <= self.bound_m


def scenario(speed: float, watchdog_ms: int) -> Scenario:
    """Straight at ``speed`` until steady, then silence, with ``watchdog_ms`` set first."""
    ramp = speed / (MAX_ACCEL * safety.WHEEL_RADIUS)
    drive = math.ceil((ramp + STEADY_S) * 10) / 10
    return Scenario(f"stop_{speed:g}_{watchdog_ms}", "stopping distance after silence",
                    (Segment("cmdvel", (speed, 0.0), drive), Segment("silence", (), SILENCE_S)),
                    settle_s=0.0, board_params={"watchdog_ms": float(watchdog_ms)})


def measure(speed: float, watchdog_ms: int, backend: str, elf: str | None = None) -> Row:
    """One cell of the table, run on ``backend``."""
    sc = scenario(speed, watchdog_ms)
    wall = time.perf_counter()
    result = runner.run(sc, backend=backend, elf=elf)
    wall = time.perf_counter() - wall
    m = result.fault_metrics()
    at = m["fault_at_s"]
    assert at is not None
    v0 = safety.speed_at(result, at)
    chair = sc.params()
    decel = min(safety.EMERGENCY_DECEL, chair.max_braking / chair.wheel_radius)
    return Row(backend, speed, watchdog_ms, v0, m["travel_after_fault_m"] or 0.0,
               m["standstill_after_fault_s"],
               safety.stopping_bound(v0, watchdog_ms, decel, chair.wheel_radius), wall)


def table(rows: list[Row]) -> str:
    """The rows as a Markdown table."""
    lines = ["| backend | start speed (m/s) | watchdog_ms | speed at last byte (m/s) | distance (m) "
             "| time to standstill (s) | bound (m) | within |",
             "|---|---:|---:|---:|---:|---:|---:|:---:|"]
    for r in rows:
        still = "never" if r.standstill_s is None else f"{r.standstill_s:.2f}"
        lines.append(f"| {r.backend} | {r.speed:.2f} | {r.watchdog_ms} | {r.speed_at_last_byte:.2f} "
                     f"| {r.distance_m:.2f} | {still} | {r.bound_m:.2f} | {'yes' if r.within else 'NO'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Prints the table; the exit status is 1 when a cell breaks its bound."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--backend", choices=("port", "simavr", "both"), default="both")
    ap.add_argument("--speeds", type=float, nargs="+", default=list(SPEEDS))
    ap.add_argument("--watchdog", type=int, nargs="+", default=list(WATCHDOGS))
    ap.add_argument("--elf", help="firmware ELF for the simavr backend (default: build the bundled one)")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = ap.parse_args(argv)
    backends = ("port", "simavr") if args.backend == "both" else (args.backend,)
    rows = []
    for backend in backends:
        for speed in args.speeds:
            for wd in args.watchdog:
                rows.append(measure(speed, wd, backend, args.elf))
                if not args.json:
                    print(f"  {backend} {speed} m/s watchdog {wd} ms: {rows[-1].distance_m:.2f} m "
                          f"({rows[-1].wall_s:.1f} s)", file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps([asdict(r) | {"within": r.within} for r in rows], indent=2))
    else:
        print(table(rows))
    return 0 if all(r.within for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
