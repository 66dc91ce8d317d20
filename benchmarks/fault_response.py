"""How the chair answers each bundled fault scenario (docs/safety.md): when the board
latched the fault, how fast the chair went after it, when the motors were off, when it
stood still, how far it went, and whether every bound of ``wcdrive.sim.safety`` held.

    python benchmarks/fault_response.py [--backend port|simavr|both] [--json]

Ground truth is the plant; the simavr backend also replays every firmware event on the
port (``firmware_differences``, expected 0).
"""

from __future__ import annotations

import argparse
import json
import sys

from wcdrive.sim import runner, safety
from wcdrive.sim.scenario import bundled, load


def measure(name: str, backend: str) -> dict[str, object]:
    """One scenario on one backend: its fault figures and the bounds it breaks."""
    sc = load(name)
    result = runner.run(sc, backend=backend)
    m = result.fault_metrics()
    at = m["fault_at_s"]
    latched = next((t for t, line in result.link.events if line.startswith("EVT:FAULT") and at is not None
                    and t >= at), None)
    kind, _ = safety.trigger(sc)
    return {
        "scenario": name, "backend": backend, "kind": kind, "fault_at_s": at,
        "event": next((line for t, line in result.link.events if at is not None and t >= at - 1e-9), None),
        "detected_after_s": None if latched is None or at is None else round(latched - at, 3),
        "commanded_mps": round(safety.commanded_speed(sc, at or 0.0), 3),
        "peak_after_mps": m["peak_speed_after_fault_mps"],
        "pwm_zero_after_s": m["pwm_zero_after_fault_s"],
        "standstill_after_s": m["standstill_after_fault_s"],
        "travel_after_m": m["travel_after_fault_m"],
        "max_tick_gap_ms": m["max_tick_gap_ms"],
        "firmware_differences": result.firmware_differences,
        "violations": safety.violations(sc, result),
    }


def _f(v: object, digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def table(rows: list[dict[str, object]]) -> str:
    """The rows as a Markdown table."""
    out = ["| scenario | backend | event | detected after (s) | commanded (m/s) | peak after (m/s) "
           "| PWM 0 after (s) | standstill after (s) | travel (m) | max tick gap (ms) | port vs firmware "
           "| bounds |",
           "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        diffs = "-" if r["firmware_differences"] is None else str(r["firmware_differences"])
        bounds = "kept" if not r["violations"] else "BROKEN: " + "; ".join(map(str, r["violations"]))  # type: ignore[call-overload]
        out.append(f"| {r['scenario']} | {r['backend']} | {r['event'] or '-'} | {_f(r['detected_after_s'])} "
                   f"| {_f(r['commanded_mps'])} | {_f(r['peak_after_mps'])} | {_f(r['pwm_zero_after_s'])} "
                   f"| {_f(r['standstill_after_s'])} | {_f(r['travel_after_m'])} "
                   f"| {_f(r['max_tick_gap_ms'], 1)} | {diffs} | {bounds} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Prints the table; the exit status is 1 when a bound is broken."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--backend", choices=("port", "simavr", "both"), default="both")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    backends = ("port", "simavr") if args.backend == "both" else (args.backend,)
    names = [p.stem for p in bundled() if p.stem.startswith("fault_")]
    rows = []
    for backend in backends:
        for name in names:
            rows.append(measure(name, backend))
            print(f"  {backend} {name}", file=sys.stderr, flush=True)
    print(json.dumps(rows, indent=2) if args.json else table(rows))
    return 0 if all(not r["violations"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
