"""The chair's operating envelope, swept on the port: false alarms of a healthy chair,
detection and stops of a faulty one, and what the board says beyond the envelope.

    python benchmarks/envelope.py [--quick] [--workers 2] [--seed 0] [--json]
                                  [--serial] [--failing DIR]

The drives (``wcdrive.testing.envelope``, drawn from ``RandomDraw``, so one seed gives
the same drives on every machine): uniform grades and cross-slopes, ramp bands up and
down with their level-to-ramp and ramp-to-level transitions (stopping beyond the band
or on it), every grade up to the rated grade of the drawn occupant (40 to 150 kg),
speeds up to the full-speed command (2.68 m/s), turns up to 1 rad/s, host rates 4 to
100 Hz, the default gains or one set drawn over the accepted ranges, one chair in
three with a parking brake the firmware owns (counted apart: "with a brake"). Each is a
scenario TOML run by ``wcdrive.tools.sweep`` on Dask (``run_dask``; ``--serial``: in
this process), one task a drive.

* **Healthy, inside the envelope**: any ``EVT:FAULT`` is a false fault; a limit event
  (``EVT:STALLED_ON_GRADE``, ``EVT:OVERSPEED``, ``EVT:ROLLAWAY``) is a false alarm too,
  counted apart (and apart again within 90 % of the rated grade).
* **Faulty**: the first drives again, each with one fault of each kind
  (``motor_dead``, ``encoder_cut``, ``encoder_reversed``, ``wheel_locked`` (the wheel
  and its encoder stand), ``link_cut``) at a seeded moment of its motion, on a seeded
  side. Detected: an ``EVT:FAULT`` after the fault (for ``link_cut``, the watchdog's
  ``EVT:WATCHDOG`` or a fault); pre-empted: a (false) fault latched before it, so the
  drive says nothing of detection. Time to stop, of the detected ones:
  ``standstill_after_fault_s`` (from the fault until the chair is still to the end of
  the run, 3.5 s after the commanded stop), and ``travel_after_fault_m``.
* **Beyond the envelope**: 1:8 kerb cuts up and down; any ``EVT:FAULT`` is wrong there
  (only limit events).

Prints markdown tables for docs/safety.md (``--json``: the figures and every failing
drive with its TOML); ``--failing DIR`` writes each failing healthy drive's TOML there
(``wcdrive sim DIR/FILE.toml`` replays it). Sizes: ``--quick`` (tests, a few seconds)
and the full one (``SIZES``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wcdrive.hil.traces import RandomDraw
from wcdrive.testing import envelope as ev
from wcdrive.tools import sweep


@dataclass(frozen=True)
class Size:
    """How many drives: healthy inside, beyond (kerb cuts), faulty per fault kind."""

    healthy: int
    beyond: int
    faulty: int


SIZES = {"quick": Size(healthy=60, beyond=12, faulty=12), "full": Size(healthy=3000, beyond=300, faulty=400)}
#: Seeds of the draws: one stream per group, ``seed * _STRIDE + offset + index``.
_STRIDE = 10_000_000


@dataclass(frozen=True)
class Case:
    """One run: its group (``healthy``, ``beyond`` or a fault kind) and its drive."""

    run: int
    group: str
    drive: ev.Drive

    @property
    def name(self) -> str:
        """The scenario's name: ``envelope_<group>_<run>``."""
        return f"envelope_{self.group}_{self.run}"


def cases(size: Size, seed: int = 0) -> list[Case]:
    """The drives of a sweep of ``size``: the healthy ones, the kerb cuts, then each
    fault kind on the first ``size.faulty`` healthy drives."""
    base = seed * _STRIDE
    healthy = [ev.drive(RandomDraw(base + i), ev.INSIDE) for i in range(size.healthy)]
    beyond = [ev.drive(RandomDraw(base + 1_000_000 + i), ev.BEYOND) for i in range(size.beyond)]
    drives: list[tuple[str, ev.Drive]] = [("healthy", d) for d in healthy] + [("beyond", d) for d in beyond]
    for k, kind in enumerate(ev.FAULT_KINDS):
        drives += [(kind, ev.faulty(RandomDraw(base + 2_000_000 * (k + 2) + i), d, kind))
                   for i, d in enumerate(healthy[:size.faulty])]
    return [Case(i, group, d) for i, (group, d) in enumerate(drives)]


def points(runs: Sequence[Case]) -> list[dict[str, Any]]:
    """The runs as ``wcdrive.tools.sweep`` points, each with its scenario TOML."""
    return [{"run": c.run, "scenario": c.name, "toml": c.drive.toml(c.name), "backend": "port", "seed": 0,
             "dt": 0.001, "params": {}, "chair": {}} for c in runs]


def run(runs: Sequence[Case], workers: int, serial: bool = False,
        on_row: Callable[[dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:
    """The sweep's rows (sorted by run): on a Dask ``LocalCluster`` of ``workers``, or
    in this process."""
    pts = points(runs)
    rows_it = sweep.run_serial(pts) if serial else sweep.run_dask(pts, workers=workers)
    rows, interrupted = sweep.collect(rows_it, on_row)
    if interrupted:
        raise KeyboardInterrupt
    return sorted(rows, key=lambda r: r["run"])


# ---- the figures ------------------------------------------------------------------------
def _events(row: dict[str, Any]) -> list[list[Any]]:
    return json.loads(row["events"]) if row.get("events") else []


def _stat(values: list[float], how: str) -> float | None:
    if not values:
        return None
    if how == "median":
        return round(statistics.median(values), 3)
    if how == "p95":
        return round(sorted(values)[min(len(values) - 1, int(0.95 * len(values)))], 3)
    return round(max(values), 3)


def alarms(runs: Sequence[Case], rows: Sequence[dict[str, Any]], group: str) -> dict[str, dict[str, Any]]:
    """Per drive class of ``group`` (``healthy`` or ``beyond``) and overall: drives,
    those with an ``EVT:FAULT`` (and the kinds), with a limit event, and with a limit
    event within 90 % of the rated grade."""
    out: dict[str, dict[str, Any]] = {}
    for c, row in zip(runs, rows, strict=True):
        if c.group != group:
            continue
        verdict = ev.judge(_events(row))
        for key in (c.drive.case, *(("with a brake",) if c.drive.brake else ()), "all"):
            s = out.setdefault(key, {"drives": 0, "fault": 0, "kinds": {}, "limit": 0, "limit_90": 0,
                                     "errors": 0})
            s["drives"] += 1
            s["errors"] += bool(row.get("error"))
            if verdict.faults:
                s["fault"] += 1
                name = verdict.faults[0][1].removeprefix("EVT:FAULT,")
                s["kinds"][name] = s["kinds"].get(name, 0) + 1
            if verdict.limits:
                s["limit"] += 1
                s["limit_90"] += c.drive.grade_fraction <= 0.9
    return dict(sorted(out.items(), key=lambda kv: (kv[0] == "all", kv[0])))


def by_grade(runs: Sequence[Case], rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """The healthy drives with an ``EVT:FAULT``, by the grade's share of the rated grade."""
    bins = (("level to 50 %", 0.5), ("50 to 70 %", 0.7), ("70 to 90 %", 0.9), ("90 to 100 %", 1.0 + 1e-9))
    out = {label: {"drives": 0, "fault": 0} for label, _ in bins}
    for c, row in zip(runs, rows, strict=True):
        if c.group == "healthy":
            label = next(lbl for lbl, hi in bins if c.drive.grade_fraction < hi or hi > 1)
            out[label]["drives"] += 1
            out[label]["fault"] += bool(ev.judge(_events(row)).faults)
    return out


def detection(runs: Sequence[Case], rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per fault kind: drives, detected, missed, pre-empted (a fault latched before the
    injected one), named on the right side, the detection latency and, of the detected
    ones, the time and distance to a standstill after the fault (``never_still``: the
    chair still moved at the end of the run)."""
    out: dict[str, dict[str, Any]] = {}
    for c, row in zip(runs, rows, strict=True):
        if c.group not in ev.FAULT_KINDS:
            continue
        s = out.setdefault(c.group, {"drives": 0, "detected": 0, "missed": 0, "pre_empted": 0,
                                     "right_side": 0, "errors": 0, "latency": [], "standstill": [],
                                     "never_still": 0, "travel": []})
        s["drives"] += 1
        if row.get("error"):
            s["errors"] += 1
            continue
        at = row.get("fault_at_s")
        at = float(at) if at not in (None, "") else float(c.drive.fault_at or 0.0)
        events = [(float(t), str(line)) for t, line in _events(row)]
        if any(line.startswith("EVT:FAULT") and t < at - 1e-9 for t, line in events):
            s["pre_empted"] += 1
            continue
        wanted = ("EVT:FAULT", "EVT:WATCHDOG") if c.group == "link_cut" else ("EVT:FAULT",)
        found = [(t, line) for t, line in events if line.startswith(wanted) and t >= at - 1e-9]
        if not found:
            s["missed"] += 1
            continue
        s["detected"] += 1
        s["latency"].append(found[0][0] - at)
        side = c.drive.fault_side
        s["right_side"] += side is None or found[0][1].endswith("_L" if side == "left" else "_R")
        still = row.get("standstill_after_fault_s")
        if still is None:
            s["never_still"] += 1
        else:
            s["standstill"].append(float(still))
        if row.get("travel_after_fault_m") is not None:
            s["travel"].append(float(row["travel_after_fault_m"]))
    for s in out.values():
        for key in ("latency", "standstill", "travel"):
            values = s.pop(key)
            s[key] = {how: _stat(values, how) for how in ("median", "p95", "max")}
    return out


def failing(runs: Sequence[Case], rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every healthy drive (inside or beyond) that latched an ``EVT:FAULT``, or inside
    the envelope sent a limit event, with its events and TOML."""
    out = []
    for c, row in zip(runs, rows, strict=True):
        if c.group not in ("healthy", "beyond"):
            continue
        verdict = ev.judge(_events(row))
        if verdict.faults or (c.group == "healthy" and verdict.limits):
            out.append({"run": c.run, "name": c.name, "group": c.group, "class": c.drive.case,
                        "drive": c.drive.describe(), "faults": verdict.faults, "limits": verdict.limits,
                        "toml": c.drive.toml(c.name)})
    return out


def _fmt(v: float | None, unit: str = "") -> str:
    return "-" if v is None else f"{v:.2f}{unit}"


def markdown(report: dict[str, Any]) -> str:
    """The figures as the markdown tables of docs/safety.md."""
    out = [f"Healthy chair inside the envelope ({report['size']}, seed {report['seed']}):", "",
           "| drives | n | EVT:FAULT | faults latched | limit events | of them within 90 % of rated |",
           "|---|---:|---:|---|---:|---:|"]
    for name, s in report["healthy"].items():
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(s["kinds"].items())) or "-"
        out.append(f"| {name} | {s['drives']} | {s['fault']} | {kinds} | {s['limit']} | {s['limit_90']} |")
    out += ["", "| grade, share of the rated grade | drives | EVT:FAULT |", "|---|---:|---:|"]
    out += [f"| {k} | {s['drives']} | {s['fault']} |" for k, s in report["by_grade"].items()]
    out += ["", "Beyond the envelope (1:8 kerb cuts; only limit events are right there):", "",
            "| drives | n | EVT:FAULT | faults latched | limit events |", "|---|---:|---:|---|---:|"]
    for name, s in report["beyond"].items():
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(s["kinds"].items())) or "-"
        out.append(f"| {name} | {s['drives']} | {s['fault']} | {kinds} | {s['limit']} |")
    out += ["", "Faults injected at a seeded moment of the same drives:", "",
            "| fault | drives | detected | missed | pre-empted | right side | detection (median / max, s) "
            "| to a standstill (median / p95 / max, s) | never still | travel after (median / max, m) |",
            "|---|---:|---:|---:|---:|---:|---|---|---:|---|"]
    for kind, s in report["faulty"].items():
        lat, still, travel = s["latency"], s["standstill"], s["travel"]
        out.append(f"| {kind} | {s['drives']} | {s['detected']} | {s['missed']} | {s['pre_empted']} "
                   f"| {s['right_side']} | {_fmt(lat['median'])} / {_fmt(lat['max'])} "
                   f"| {_fmt(still['median'])} / {_fmt(still['p95'])} / {_fmt(still['max'])} "
                   f"| {s['never_still']} | {_fmt(travel['median'])} / {_fmt(travel['max'])} |")
    out += ["", f"{report['runs']} runs on {report['workers']} workers in {report['wall_s']:.1f} s"
            f"{'; errors: ' + str(report['errors']) if report['errors'] else ''}."]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Runs the sweep the arguments ask for and prints its figures; 0 unless a run
    raised."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"the small size ({SIZES['quick']})")
    ap.add_argument("--seed", type=int, default=0, help="the draws' seed (default 0)")
    ap.add_argument("--workers", type=int, default=2, help="Dask workers (default 2)")
    ap.add_argument("--serial", action="store_true", help="run in this process, without Dask")
    ap.add_argument("--json", action="store_true", help="the figures and the failing drives as JSON")
    ap.add_argument("--failing", type=Path, metavar="DIR",
                    help="write each failing healthy drive's TOML here")
    args = ap.parse_args(argv)
    size_name = "quick" if args.quick else "full"
    runs = cases(SIZES[size_name], args.seed)
    t0 = time.perf_counter()
    rows = run(runs, args.workers, args.serial)
    wall = time.perf_counter() - t0
    bad = failing(runs, rows)
    errors = [(r["run"], r["error"]) for r in rows if r.get("error")]
    report = {"size": size_name, "seed": args.seed, "workers": 0 if args.serial else args.workers,
              "runs": len(rows), "wall_s": round(wall, 1), "errors": len(errors),
              "healthy": alarms(runs, rows, "healthy"), "by_grade": by_grade(runs, rows),
              "beyond": alarms(runs, rows, "beyond"), "faulty": detection(runs, rows)}
    if args.failing:
        args.failing.mkdir(parents=True, exist_ok=True)
        for f in bad:
            (args.failing / f"{f['name']}.toml").write_text(f["toml"])
    if args.json:
        print(json.dumps({**report, "failing": bad, "error_runs": errors}, indent=1))
    else:
        print(markdown(report))
        for f in bad[:3]:
            print(f"\n{f['name']}: {f['drive']}\n  {list(f['faults'])} {list(f['limits'])}")
        for run_index, message in errors:
            print(f"run {run_index}: {message}", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
