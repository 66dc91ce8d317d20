"""The motor rule (``noEffect`` and the both-wheels limit, ``atLimit``) over two sweeps,
watched from the plant: how often a healthy chair is stopped by it, and how often a
dead motor goes undetected.

    python benchmarks/motor_rule.py [--json] [--cases]

* **False alarms.** A healthy chair drives ``cmdvel = [speed, turn]`` for 6 s, falls
  silent for ``gap`` s (the watchdog stops it at 0.5 s), and drives on for 3 s: speeds
  0.5 to 2.68 m/s, turns 0 to 0.8 rad/s, on the level and 4 degrees up and down. Any
  ``EVT:FAULT``, ``EVT:ROLLAWAY``, ``EVT:OVERSPEED`` or ``EVT:STALLED_ON_GRADE`` is a
  false alarm. The same drives without the silence tell the watchdog's share.
* **Turning on a slope.** A healthy chair turns for 10 s at 0.2, 0.4 and 0.8 rad/s
  either way, at 0.3 to 1.5 m/s, on 2 and 4 degree slopes, starting with the slope's
  downhill ahead, to the left, behind and to the right: it faces up, across and down
  the slope in turn. Any alarm is a false alarm.
* **Detection.** ``motor_dead`` on one side 2.5 s into a 15 s drive: speeds 0.3 to
  1.5 m/s, straight and turning, on the level, 1:12 down, 2 degrees up. The first alarm
  after the fault, and where none came, how far the chair went and turned after it.

The port runs every case (the firmware in simavr gives the same bits: ``wcdrive
verify``). Each sweep takes seconds.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import tempfile
from pathlib import Path

import numpy as np

from wcdrive.sim import runner, scenario

ALARMS = ("EVT:FAULT", "EVT:ROLLAWAY", "EVT:OVERSPEED", "EVT:STALLED_ON_GRADE")
DEAD_AT = 3.0


def _run(tmp: Path, text: str) -> runner.SimResult:
    path = tmp / "case.toml"
    path.write_text(text)
    return runner.run(scenario.load(str(path)))


def _head(slope: float, heading: float) -> str:
    return (f'name = "motor_rule"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
            f"[world]\nslope_deg = {slope}\ndownhill_heading_deg = {heading}\n")


def _alarms(r: runner.SimResult, after: float = -1.0) -> list[tuple[float, str]]:
    return [(t, line) for t, line in r.link.events if line.startswith(ALARMS) and t > after]


GRADES = {"level": (0.0, 0.0), "4 deg down": (4.0, 0.0), "4 deg up": (4.0, 180.0)}


def false_alarms(tmp: Path) -> list[dict[str, object]]:
    """The healthy drives, with and without the silence."""
    rows = []
    for speed, turn, gap, grade in itertools.product([0.5, 1.0, 1.5, 2.0, 2.68], [0.0, 0.2, -0.4, 0.8],
                                                     [0.0, 0.5, 0.6, 0.9], GRADES):
        text = _head(*GRADES[grade]) + f"[[segment]]\ncmdvel = [{speed}, {turn}]\nduration = 6.0\n"
        if gap:
            text += f"[[segment]]\nsilence = true\nduration = {gap}\n"
        text += f"[[segment]]\ncmdvel = [{speed}, {turn}]\nduration = 3.0\n"
        r = _run(tmp, text)
        rows.append({"speed": speed, "turn": turn, "gap": gap, "grade": grade,
                     "alarms": [line for _, line in _alarms(r)]})
    return rows


def slope_turns(tmp: Path) -> list[dict[str, object]]:
    """The healthy turns on a slope."""
    rows = []
    for speed, turn, sign, slope, heading in itertools.product([0.3, 0.5, 1.0, 1.5], [0.2, 0.4, 0.8], [1, -1],
                                                                [2.0, 4.0], [0.0, 90.0, 180.0, 270.0]):
        text = _head(slope, heading) + f"[[segment]]\ncmdvel = [{speed}, {sign * turn}]\nduration = 10.0\n"
        r = _run(tmp, text)
        found = _alarms(r)
        rows.append({"speed": speed, "turn": sign * turn, "slope_deg": slope, "downhill_heading_deg": heading,
                     "alarms": [line for _, line in found], "first_alarm_s": found[0][0] if found else None})
    return rows


DEAD_GRADES = {"level": (0.0, 0.0), "1:12 down": (math.degrees(math.atan(1 / 12)), 0.0),
               "2 deg up": (2.0, 180.0), "4 deg down": (4.0, 0.0), "4 deg across": (4.0, 90.0)}


def detection(tmp: Path) -> list[dict[str, object]]:
    """The dead-motor drives: the first alarm after the fault, or the chair's path after it."""
    rows = []
    for speed, turn, side, grade in itertools.product([0.3, 0.5, 1.0, 1.5], [0.0, 0.3, -0.3],
                                                      ["left", "right"], DEAD_GRADES):
        text = (_head(*DEAD_GRADES[grade]) + f"[[segment]]\ncmdvel = [{speed}, {turn}]\nduration = 15.0\n"
                f'[[fault]]\nat = {DEAD_AT}\nkind = "motor_dead"\nside = "{side}"\n')
        r = _run(tmp, text)
        at = r.fault_at if r.fault_at is not None else DEAD_AT
        first = _alarms(r, at)
        after = r.board.tick_time >= at
        pose = r.truth.pose
        i0 = int(np.argmax(after))
        travel = float(np.sum(np.hypot(np.diff(pose[i0:, 0]), np.diff(pose[i0:, 1]))))
        turned = math.degrees(abs(float(pose[-1, 2] - pose[i0, 2])))
        rows.append({"speed": speed, "turn": turn, "side": side, "grade": grade,
                     "detected_after_s": None if not first else round(first[0][0] - at, 3),
                     "event": None if not first else first[0][1],
                     "travel_after_m": round(travel, 2), "turned_after_deg": round(turned, 1)})
    return rows


def summary(fa: list[dict[str, object]], det: list[dict[str, object]], turns: list[dict[str, object]]) -> str:
    """The figures as Markdown."""
    out = ["| false alarms | drives | with an alarm |", "|---|---:|---:|"]
    for label, silent in (("no silence", False), ("watchdog stop, then on", True)):
        rows = [r for r in fa if (r["gap"] != 0.0) == silent]
        out.append(f"| {label} | {len(rows)} | {sum(bool(r['alarms']) for r in rows)} |")
    for slope in (2.0, 4.0):
        rows = [r for r in turns if r["slope_deg"] == slope]
        out.append(f"| turning 10 s on a {slope:g} degree slope | {len(rows)} | "
                   f"{sum(bool(r['alarms']) for r in rows)} |")
    out += ["", "| dead motor at (m/s) | drives | within 1 s | within 4 s | within 12.5 s | never |",
            "|---:|---:|---:|---:|---:|---:|"]
    for speed in sorted({float(r["speed"]) for r in det}):  # type: ignore[arg-type]
        rows = [r for r in det if r["speed"] == speed]
        lat = [r["detected_after_s"] for r in rows]
        out.append(f"| {speed} | {len(rows)} | {sum(v is not None and v <= 1.0 for v in lat)} "  # type: ignore[operator]
                   f"| {sum(v is not None and v <= 4.0 for v in lat)} | {sum(v is not None for v in lat)} "  # type: ignore[operator]
                   f"| {sum(v is None for v in lat)} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", action="store_true", help="every case as JSON")
    ap.add_argument("--cases", action="store_true", help="list the false alarms and the missed dead motors")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        fa, det, turns = false_alarms(Path(d)), detection(Path(d)), slope_turns(Path(d))
    if args.json:
        print(json.dumps({"false_alarms": fa, "detection": det, "slope_turns": turns}, indent=1))
        return
    print(summary(fa, det, turns))
    if args.cases:
        print()
        for r in fa:
            if r["alarms"]:
                print(f"false alarm: {r['speed']} m/s, turn {r['turn']}, gap {r['gap']} s, {r['grade']}: "
                      f"{r['alarms']}")
        for r in turns:
            if r["alarms"]:
                print(f"false alarm turning: {r['speed']} m/s, turn {r['turn']}, {r['slope_deg']} deg, "
                      f"downhill at {r['downhill_heading_deg']} deg: {r['alarms']} at {r['first_alarm_s']} s")
        for r in det:
            if r["detected_after_s"] is None:
                print(f"missed: {r['side']} dead at {r['speed']} m/s, turn {r['turn']}, {r['grade']}: "
                      f"{r['travel_after_m']} m and {r['turned_after_deg']} deg after the fault")


if __name__ == "__main__":
    main()
