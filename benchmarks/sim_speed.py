"""The simulation's speed, the figures of docs/benchmarks.md's "Simulation
speed" table, in one run so that the machine's load weighs on all of them alike:

* every bundled scenario's real-time factor on the port backend (the median of
  ``--runs`` runs; ``wcdrive.sim.runner.run`` without the EKFs, whose filterpy updates at
  the gyro's 400 Hz cost more than the rest of the run: ``--ekf`` adds a column with
  them, as ``wcdrive sim --ekf`` runs them), and beside it one run on the loop's
  reference path (``PortLoop(stepped=True)``, every Timer0 overflow in turn: the loop as
  it was);
* the command itself: ``wcdrive sim corridor_100m --no-plots --json`` in ``--cli`` fresh
  processes, the median of the ``real_time_factor`` each reports;
* port + plant against simavr + plant on one scenario, measured side by side (3 port
  runs, simavr, 3 port runs: the ratio of the port's median to simavr's run), with the firmware
  differences the simavr run found (0 expected).

    python benchmarks/sim_speed.py            # 5 runs a scenario, 5 CLI runs, simavr on step_response
    python benchmarks/sim_speed.py --quick    # 3 scenarios, 1 run, no CLI runs, simavr on fault_reset
"""

from __future__ import annotations

import argparse
import functools
import json
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from wcdrive.boards.port_loop import PortLoop
from wcdrive.sim import runner
from wcdrive.sim.scenario import bundled, load

QUICK = ("square", "fault_reset", "fault_encoder_noise")


def rtf(name: str, *, stepped: bool = False, ekf: bool = False) -> float:
    """One port run of scenario ``name``: its real-time factor."""
    original = runner.PortLoop
    if stepped:
        runner.PortLoop = functools.partial(PortLoop, stepped=True)  # type: ignore[assignment, misc]
    try:
        return runner.run(load(name), ekf=ekf).real_time_factor
    finally:
        runner.PortLoop = original  # type: ignore[misc]


def side_by_side(name: str, runs: int = 3) -> dict:
    """Port, simavr, port on scenario ``name``: the port's figure is the median of
    ``runs`` runs just before the simavr run and ``runs`` just after it (a port run
    takes milliseconds, so one slow run weighs less in a median of several)."""
    for _ in range(2):         # warm-up, not counted: after the CLI's child processes the
        rtf(name)              # first runs here measured at half speed (an idle core)
    before = [rtf(name) for _ in range(runs)]
    sim = runner.run(load(name), backend="simavr")
    after = [rtf(name) for _ in range(runs)]
    port = statistics.median(before + after)
    return {"port": port, "simavr": sim.real_time_factor, "ratio": port / sim.real_time_factor,
            "differences": float(sim.firmware_differences or 0), "simulated": sim.duration,
            "port_runs": before + after}


def cli_rtf(name: str = "corridor_100m") -> float:
    """``wcdrive sim NAME --no-plots --json`` in a fresh process: the real-time factor it
    reports."""
    out = subprocess.run([sys.executable, "-m", "wcdrive", "sim", name, "--no-plots", "--json"],
                         capture_output=True, text=True, check=True).stdout
    return float(json.loads(out)[0]["real_time_factor"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="3 scenarios, 1 run each, simavr on fault_reset")
    parser.add_argument("--runs", type=int, default=None,
                        help="runs per scenario (default 5; 1 with --quick)")
    parser.add_argument("--no-simavr", action="store_true")
    parser.add_argument("--ekf", action="store_true", help="a column with the EKFs on (wcdrive sim --ekf)")
    parser.add_argument("--cli", type=int, default=None,
                        help="fresh-process runs of wcdrive sim corridor_100m --no-plots --json (default 5; "
                             "0 with --quick)")
    parser.add_argument("scenarios", nargs="*")
    args = parser.parse_args(argv)
    runs = args.runs or (1 if args.quick else 5)
    names = args.scenarios or (list(QUICK) if args.quick else [p.stem for p in bundled()])
    for name in names[:1]:
        rtf(name)                       # builds and loads the kernel, warms the parse caches
    head = f"| scenario | real-time factor (median of {runs}) | reference loop (stepped) | simulated s |"
    rule = "|---|---:|---:|---:|"
    if args.ekf:
        head += " with the EKFs (wcdrive sim --ekf) |"
        rule += "---:|"
    print(head)
    print(rule)
    for name in names:
        figures = [rtf(name) for _ in range(runs)]
        row = (f"| {name} | {statistics.median(figures):,.0f}x | {rtf(name, stepped=True):,.0f}x "
               f"| {load(name).duration:.1f} |")
        if args.ekf:
            row += f" {rtf(name, ekf=True):,.0f}x |"
        print(row, flush=True)
    cli_runs = (0 if args.quick else 5) if args.cli is None else args.cli
    if cli_runs:
        figures = [cli_rtf() for _ in range(cli_runs)]
        print(f"\nwcdrive sim corridor_100m --no-plots --json, {cli_runs} fresh processes: real_time_factor "
              f"median {statistics.median(figures):,.0f}x (" + ", ".join(f"{f:,.0f}" for f in figures) + ")")
    if not args.no_simavr:
        name = "fault_reset" if args.quick else "step_response"
        s = side_by_side(name)
        print(f"\nport + plant vs simavr + plant ({name}, {s['simulated']:.1f} s, side by side): "
              f"{s['port']:,.0f}x vs {s['simavr']:.2f}x real time, ratio {s['ratio']:,.0f}; "
              f"firmware differences {s['differences']:.0f} (port runs before and after simavr: "
              + ", ".join(f"{f:,.0f}" for f in s["port_runs"]) + ")")
    return 0


if __name__ == "__main__":
    sys.exit(main())
