"""ISO 7176-3- and 7176-6-style tables on a grade (docs/safety.md, "On a grade"): how
the chair stops and stays stopped, and how fast it goes, on the level, 1:20, 1:12 and
the rated grade, measured on the plant's ground truth.

    python benchmarks/iso7176.py [--backend port|simavr|both] [--quick] [--parked 60]
        [--elf PATH] [--json]

The 7176-3-style table has a row per grade and direction (the level once; every other
grade facing uphill and facing downhill), start speed and way of stopping. The host
drives straight at the start speed (0.5 m/s, 1.0 m/s, or the full-speed command,
``MAX_LINEAR``: the top speed the chair reaches on that grade) until steady, then either
sends stops (``command``) or goes silent so that the board's watchdog stops the chair
(``last byte``), for ``--parked`` seconds and ``ALLOWANCE_S`` more. The figures are
``SimResult.stop_metrics``: from the stop (the first stop command, or the last byte the
board received) the true speed then, the stopping distance and time to the first moment
the chair is below 0.01 m/s, the drift (the axle midpoint's largest distance from where
it came to rest) over the ``--parked`` seconds after that, and the largest speed after the
stop; and the board's events over the run. A chair that never comes to rest has its
travel after the stop instead of a drift. With a parking brake (``[chair]
parking_brake``, owned by the firmware: ``brake_fitted`` 1) every row is run again and
gets the same columns; while ``ChairParams``
has no such field, a line says so and the brake columns are left out.

The 7176-6-style table has a line per grade: the top speed (the largest forward speed
the chair reaches within ``TOP_S`` of the full-speed command, over 0.5 s) facing
uphill and facing downhill, and the time from the command to 95 % of it.

Below the tables, the issue's goals, each with whether these runs meet it.

``--quick`` (what tests/sim/test_iso7176.py runs): the level and 1:12 downhill, from
0.5 m/s, both ways of stopping, 10 s parked; the 7176-6 lines for those two grades.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from dataclasses import asdict, dataclass

import numpy as np

from wcdrive.plant import ChairParams
from wcdrive.plant.terrain import Terrain
from wcdrive.protocol.spec import real
from wcdrive.sim import runner, safety
from wcdrive.sim.result import SimResult
from wcdrive.sim.scenario import Scenario, Segment

#: m/s: the full-speed command.
MAX_LINEAR = real("MAX_LINEAR")
#: rad/s^2: the firmware's normal setpoint ramp, to size the drive.
MAX_ACCEL = real("MAX_ACCEL")
#: s the chair drives at speed after the ramp.
STEADY_S = 2.5
#: s after the stop for the chair to come to rest, before the parked time counts.
ALLOWANCE_S = 10.0
#: s of the full-speed command for the top speed, and the control ticks its speeds
#: are averaged over (a tick log row's pose is up to a physics step older than its time).
TOP_S = 8.0
WINDOW_TICKS = 10
#: m: the issue's goals for the drift over 60 s parked on 1:12 and the rated grade.
DRIFT_GOAL_M = 0.02
BRAKE_DRIFT_GOAL_M = 0.005
#: The events that are alarms (the watchdog's stop is not one).
ALARMS = ("EVT:FAULT", "EVT:ROLLAWAY", "EVT:OVERSPEED")
HAS_BRAKE = "parking_brake" in {f.name for f in dataclasses.fields(ChairParams)}
STOPS = ("command", "last byte")


@dataclass(frozen=True)
class Grade:
    """A floor to measure on: its label, and the grade (degrees)."""

    label: str
    deg: float

    def terrain(self, direction: str) -> Terrain:
        """The floor with the chair, heading +x, facing ``direction`` (up, down, level)."""
        if self.deg == 0.0:
            return Terrain()
        return Terrain(self.deg, 180.0 if direction == "up" else 0.0)

    def directions(self) -> tuple[str, ...]:
        """Up and down on a grade; once on the level."""
        return ("level",) if self.deg == 0.0 else ("up", "down")


def grades(params: ChairParams | None = None) -> list[Grade]:
    """The level, 1:20, 1:12 and the rated grade of ``params`` (the default chair and
    occupant)."""
    p = params or ChairParams()
    return [Grade("level", 0.0), Grade("1:20", math.degrees(math.atan(1 / 20))),
            Grade("1:12", math.degrees(math.atan(1 / 12))),
            Grade(f"rated ({p.occupant_mass:g} kg)", p.rated_grade())]


@dataclass
class Figures:
    """What one run gives (``SimResult.stop_metrics``): the true speed at the stop
    (m/s), the stopping distance (m) and time (s) to rest (None: never at rest), the
    drift parked (m) and the seconds it was counted over, the largest speed after the
    stop (m/s), the travel after the stop (m) and the seconds after it the run went on,
    the board's events (``EVT:`` lines, each kind once, the EEPROM's left out), the
    port-vs-firmware differences (simavr) and the wall time (s)."""

    speed_at_stop: float
    distance_m: float | None
    time_s: float | None
    drift_m: float | None
    drift_over_s: float | None
    max_after_mps: float
    travel_m: float
    after_s: float
    events: list[str]
    differences: int | None
    wall_s: float


@dataclass
class Row:
    """A row of the 7176-3-style table: the backend, grade, direction, start speed
    (m/s; ``MAX_LINEAR``: the top), way of stopping, and the figures without a brake
    and (None: not run) with one."""

    backend: str
    grade: str
    grade_deg: float
    direction: str
    start_mps: float
    stop: str
    plain: Figures
    brake: Figures | None = None


@dataclass
class TopSpeed:
    """A line of the 7176-6-style table: the backend, grade, the seconds of the
    full-speed command, facing up and facing down the top speed (m/s) and the time to
    95 % of it (s), and the port-vs-firmware differences of both runs (simavr)."""

    backend: str
    grade: str
    drive_s: float
    up_mps: float
    up_s: float
    down_mps: float
    down_s: float
    differences: int | None = None


def drive_s(speed: float) -> float:
    """s of driving: the ramp to ``speed`` at ``MAX_ACCEL``, then ``STEADY_S``, to 0.1 s."""
    ramp = speed / (MAX_ACCEL * safety.WHEEL_RADIUS)
    return math.ceil((ramp + STEADY_S) * 10) / 10


def stop_scenario(grade: Grade, direction: str, speed: float, stop: str, parked_s: float,
                  brake: bool = False) -> Scenario:
    """Straight at ``speed`` on ``grade`` facing ``direction``, then ``stop`` (stop
    commands, or silence) for ``parked_s`` and ``ALLOWANCE_S``."""
    kind = "stop" if stop == "command" else "silence"
    segments = (Segment("cmdvel", (speed, 0.0), drive_s(speed)), Segment(kind, (), parked_s + ALLOWANCE_S))
    return Scenario(f"iso7176_3_{grade.label}_{direction}_{speed:g}_{kind}", "ISO 7176-3-style stop",
                    segments, settle_s=0.0, chair={"parking_brake": True} if brake else {},
                    board_params={"brake_fitted": 1.0} if brake else {}, terrain=grade.terrain(direction))


def figures(result: SimResult, parked_s: float, wall_s: float) -> Figures:
    """The ``Figures`` of a stop run."""
    m = result.stop_metrics(parked_s=parked_s)
    at = m["stop_at_s"]
    assert at is not None, "a stop run always stops"
    rest = m["rest_at_s"]
    events: list[str] = []
    for _, line in result.link.events:
        if not line.startswith("EVT:PARAMS") and line not in events:
            events.append(line)
    return Figures(safety.speed_at(result, at + 1e-3), m["stopping_distance_m"], m["stopping_time_s"],
                   m["drift_parked_m"], None if rest is None else min(parked_s, result.duration - rest),
                   m["max_speed_after_stop_mps"] or 0.0, m["travel_after_stop_m"] or 0.0,
                   result.duration - at, events, result.firmware_differences, wall_s)


def measure(grade: Grade, direction: str, speed: float, stop: str, parked_s: float, backend: str,
            brake: bool, elf: str | None = None) -> Figures:
    """One run of ``stop_scenario`` on ``backend``, as ``Figures``."""
    wall = time.perf_counter()
    sc = stop_scenario(grade, direction, speed, stop, parked_s, brake)
    result = runner.run(sc, backend=backend, elf=elf)
    return figures(result, parked_s, time.perf_counter() - wall)


def top_speed(grade: Grade, direction: str, backend: str, drive: float = TOP_S,
              elf: str | None = None) -> tuple[float, float, int | None]:
    """(top speed in m/s, s from the command to 95 % of it, the port-vs-firmware
    differences on simavr) facing ``direction``: the
    axle midpoint's mean speed along the chair's heading (forward positive, so that
    rolling back is not speed) over ``WINDOW_TICKS`` control ticks, the time at the end
    of the first such window at 95 % of the top."""
    sc = Scenario(f"iso7176_6_{grade.label}_{direction}", "ISO 7176-6-style top speed",
                  (Segment("cmdvel", (MAX_LINEAR, 0.0), drive),), settle_s=0.0,
                  terrain=grade.terrain(direction))
    result = runner.run(sc, backend=backend, elf=elf)
    t, pose, n = result.board.tick_time, result.truth.pose, WINDOW_TICKS
    step = pose[n:, :2] - pose[:-n, :2]
    ahead = step[:, 0] * np.cos(pose[:-n, 2]) + step[:, 1] * np.sin(pose[:-n, 2])
    speed = ahead / (t[n:] - t[:-n])
    top = max(0.0, float(speed.max()))
    return top, float(t[n:][speed >= 0.95 * top][0]) - 0.02, result.firmware_differences


def _m(v: float | None) -> str:
    return "never" if v is None else f"{v:.3f}"


def _drift(f: Figures, parked_s: float) -> str:
    if f.drift_m is None:
        return f"never at rest: {f.travel_m:.2f} m in {f.after_s:.0f} s"
    short = f.drift_over_s is not None and f.drift_over_s < parked_s - 0.5
    return f"{f.drift_m:.4f}" + (f" (over {f.drift_over_s:.0f} s)" if short else "")


def _events(f: Figures) -> str:
    return ", ".join(e.removeprefix("EVT:") for e in f.events) or "-"


def stop_table(rows: list[Row], parked_s: float) -> str:
    """The 7176-3-style rows as a Markdown table."""
    start = {0.5: "0.5", 1.0: "1.0", MAX_LINEAR: "top"}
    cells = ["at stop (m/s)", "distance (m)", "time (s)", f"drift in {parked_s:g} s (m)",
             "max after (m/s)", "events"]
    brake = any(r.brake is not None for r in rows)
    simavr = any(r.plain.differences is not None for r in rows)
    head = ["backend", "grade", "facing", "from (m/s)", "stop by", *cells]
    if brake:
        head += [f"brake: {c}" for c in cells[1:]]
    if simavr:
        head.append("port vs firmware")
    align = ["---" if i < 5 or "drift" in h or h.endswith("events") else "---:" for i, h in enumerate(head)]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]

    def figs(f: Figures) -> list[str]:
        return [_m(f.distance_m), _m(f.time_s), _drift(f, parked_s), f"{f.max_after_mps:.3f}", _events(f)]

    for r in rows:
        row = [r.backend, r.grade, r.direction, start.get(r.start_mps, f"{r.start_mps:g}"), r.stop,
               f"{r.plain.speed_at_stop:.2f}", *figs(r.plain)]
        if brake:
            row += figs(r.brake) if r.brake is not None else ["-"] * (len(cells) - 1)
        if simavr:
            diffs = [f.differences for f in (r.plain, r.brake) if f is not None and f.differences is not None]
            row.append(str(sum(diffs)) if diffs else "-")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def top_table(tops: list[TopSpeed]) -> str:
    """The 7176-6-style lines as a Markdown table."""
    simavr = any(t.differences is not None for t in tops)
    lines = ["| backend | grade | top speed facing up (m/s) | time to it (s) | top speed facing down (m/s) "
             "| time to it (s) |" + (" port vs firmware |" if simavr else ""),
             "|---|---|---:|---:|---:|---:|" + ("---:|" if simavr else "")]

    def time_to(s: float, drive: float) -> str:
        # 95 % of the top only in the drive's last half second: it was still speeding up
        return f"{s:.2f}" + (" (still rising)" if s > drive - 0.5 else "")

    for t in tops:
        diffs = f" {'-' if t.differences is None else t.differences} |" if simavr else ""
        lines.append(f"| {t.backend} | {t.grade} | {t.up_mps:.2f} | {time_to(t.up_s, t.drive_s)} "
                     f"| {t.down_mps:.2f} | {time_to(t.down_s, t.drive_s)} |{diffs}")
    return "\n".join(lines)


def _yes(ok: bool) -> str:
    return "yes" if ok else "NO"


def goals(rows: list[Row], all_grades: list[Grade], parked_s: float) -> list[str]:
    """The issue's goals these rows bear on (``parked_s`` parked after each stop), each
    with ``yes`` or ``NO`` and the figure."""
    out = []
    steep = {g.label for g in all_grades[2:]}         # 1:12 and the rated grade
    for which, limit in (("plain", DRIFT_GOAL_M), ("brake", BRAKE_DRIFT_GOAL_M)):
        found = [f for r in rows if r.grade in steep and (f := getattr(r, which)) is not None]
        if not found:
            continue
        worst = max(math.inf if f.drift_m is None else f.drift_m for f in found)
        what = "without a brake" if which == "plain" else "with a brake"
        figure = "never at rest" if worst == math.inf else f"{worst:.4f} m"
        out.append(f"- parked on 1:12 and the rated grade {what}, drift <= {limit} m over {parked_s:g} s "
                   f"after every stop: {_yes(worst <= limit)} (worst: {figure})")
    chair, twelve = ChairParams(), all_grades[2]
    for backend in sorted({r.backend for r in rows}):
        level = _cell(rows, backend, "level", "level")
        down = _cell(rows, backend, twelve.label, "down")
        if level is None or down is None or level.plain.distance_m is None:
            continue
        v = down.plain.speed_at_stop
        pull = 9.81 * math.sin(math.radians(twelve.deg))
        bound = level.plain.distance_m + v * v / (2 * (chair.max_braking - pull)) \
            - v * v / (2 * chair.max_braking)
        got, drift = down.plain.distance_m, down.plain.drift_m
        ok = got is not None and got <= bound and drift is not None and drift <= DRIFT_GOAL_M
        out.append(f"- {backend}: downhill on 1:12 from 1.0 m/s, the stop command brings the chair to rest "
                   f"within the level distance plus the grade's extra ({bound:.2f} m) and it stays at rest: "
                   f"{_yes(ok)} (distance {_m(got)} m, drift {_drift(down.plain, parked_s)})")
    alarms = sorted({e for r in rows for f in (r.plain, r.brake) if f is not None for e in f.events
                     if e.startswith(ALARMS)})
    out.append("- no FAULT, ROLLAWAY or OVERSPEED on any of these drives (all within the rated grade): "
               + (_yes(True) if not alarms else f"{_yes(False)} ({', '.join(alarms)})"))
    return out


def _cell(rows: list[Row], backend: str, grade: str, direction: str) -> Row | None:
    """The row from 1.0 m/s stopped by a command, on that backend, grade and facing."""
    return next((r for r in rows if r.backend == backend and r.grade == grade and r.direction == direction
                 and r.start_mps == 1.0 and r.stop == "command"), None)


def run(backend: str, chosen: list[Grade], speeds: tuple[float, ...], parked_s: float, quick: bool,
        elf: str | None = None, log: bool = True, jobs: int = 1) -> tuple[list[Row], list[TopSpeed]]:
    """The rows and the top-speed lines on ``backend`` (``quick``: on a grade, facing
    downhill only), the runs spread over ``jobs`` processes; ``log`` prints each row's
    drift to stderr."""
    cells = [(grade, direction, speed, stop) for grade in chosen
             for direction in (("down",) if quick and grade.deg else grade.directions())
             for speed in speeds for stop in STOPS]
    brakes = (False, True) if HAS_BRAKE else (False,)
    runs = [(g, d, v, s, parked_s, backend, b, elf) for g, d, v, s in cells for b in brakes]
    climbs = [(g, d, backend, TOP_S, elf) for g in chosen
              for d in (("up",) if g.deg == 0.0 else ("up", "down"))]
    with ProcessPoolExecutor(max_workers=jobs) if jobs > 1 else nullcontext() as pool:
        each = map if pool is None else pool.map
        measured = list(each(measure, *zip(*runs, strict=True)))
        climbed = list(each(top_speed, *zip(*climbs, strict=True)))
    rows: list[Row] = []
    for k, (grade, direction, speed, stop) in enumerate(cells):
        plain = measured[k * len(brakes)]
        braked = measured[k * len(brakes) + 1] if HAS_BRAKE else None
        rows.append(Row(backend, grade.label, grade.deg, direction, speed, stop, plain, braked))
        if log:
            print(f"  {backend} {grade.label} {direction} {speed:g} m/s {stop}: "
                  f"{_drift(plain, parked_s)} ({plain.wall_s:.1f} s)", file=sys.stderr, flush=True)
    tops: list[TopSpeed] = []
    speeds_of = iter(climbed)
    for grade in chosen:
        up = next(speeds_of)
        down = up if grade.deg == 0.0 else next(speeds_of)
        counts = [d for _, _, d in ((up,) if grade.deg == 0.0 else (up, down)) if d is not None]
        diffs = sum(counts) if counts else None
        tops.append(TopSpeed(backend, grade.label, TOP_S, *up[:2], *down[:2], diffs))
    return rows, tops


def main(argv: list[str] | None = None) -> int:
    """Prints the tables and the goals (``--json``: the rows)."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--backend", choices=("port", "simavr", "both"), default="port")
    ap.add_argument("--quick", action="store_true",
                    help="the level and 1:12 downhill from 0.5 m/s, 10 s parked")
    ap.add_argument("--parked", type=float, default=None,
                    help="s parked after the stop (default 60; quick 10)")
    ap.add_argument("--elf", help="firmware ELF for the simavr backend (default: build the bundled one)")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    ap.add_argument("--jobs", type=int, default=1, help="processes to spread the runs over (default 1)")
    args = ap.parse_args(argv)
    parked = args.parked if args.parked is not None else (10.0 if args.quick else 60.0)
    every = grades()
    chosen = [every[0], every[2]] if args.quick else every
    speeds = (0.5,) if args.quick else (0.5, 1.0, MAX_LINEAR)
    rows: list[Row] = []
    tops: list[TopSpeed] = []
    for backend in ("port", "simavr") if args.backend == "both" else (args.backend,):
        got = run(backend, chosen, speeds, parked, args.quick, args.elf, log=not args.json, jobs=args.jobs)
        rows += got[0]
        tops += got[1]
    if args.json:
        print(json.dumps({"rows": [asdict(r) for r in rows], "top_speeds": [asdict(t) for t in tops]},
                         indent=2))
        return 0
    print(f"ISO 7176-3-style stops ({', '.join(f'{g.label} = {g.deg:.2f} deg' for g in chosen if g.deg)}; "
          f"watchdog_ms {safety.WATCHDOG_MS:g}):\n")
    if not HAS_BRAKE:
        print("(no brake columns: ChairParams has no parking_brake field yet)\n")
    print(stop_table(rows, parked))
    print(f"\nISO 7176-6-style top speed (the full-speed command, {MAX_LINEAR:g} m/s, for {TOP_S:g} s; "
          "the time to 95 % of it):\n")
    print(top_table(tops))
    print("\nGoals:\n")
    print("\n".join(goals(rows, every, parked)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
