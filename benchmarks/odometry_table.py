"""The odometry comparison of docs/odometry.md (seed 002's: position-based and
velocity-based wheel odometry and the EKF, against ground truth), on the bundled
scenarios without faults.

    python benchmarks/odometry_table.py [--backend port|simavr] [--seed N] [--scenarios ...]

Each scenario runs with the host's EKFs (``runner.run(..., ekf=True)``). For every
estimate the table gives the final position error (m), the RMS position error over
the run (m, at every control tick) and the final heading error (deg), against the
plant's ground truth. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from wcdrive.sim import runner, scenario

ESTIMATES = (("wheel", "position"), ("velocity", "velocity"), ("gyro", "wheels + gyro"),
             ("ekf", "EKF seed 000"), ("ekf_vel", "EKF wheel vel."))


def default_scenarios() -> list[str]:
    """Every bundled scenario without a fault, a silence or a watchdog stop."""
    out = []
    for path in scenario.bundled():
        sc = scenario.load(str(path))
        if sc.faults or any(s.kind == "silence" for s in sc.segments) or sc.name == "watchdog":
            continue
        out.append(sc.name)
    return out


def row(result: runner.SimResult) -> list[str]:
    cells = [result.scenario, f"{result.duration:.1f}"]
    truth = result.truth.pose
    for key, _ in ESTIMATES:
        est = getattr(result.odometry, key)
        assert est is not None
        final = math.hypot(*(est[-1, :2] - truth[-1, :2]))
        rms = float(np.sqrt(np.mean(np.sum((est[:, :2] - truth[:, :2]) ** 2, axis=1))))
        heading = math.degrees(math.remainder(est[-1, 2] - truth[-1, 2], 2 * math.pi))
        cells.append(f"{final:.3f} / {rms:.3f} / {heading:+.2f}")
    return cells


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", choices=("port", "simavr"), default="port")
    ap.add_argument("--seed", type=int, default=0, help="gyro noise seed")
    ap.add_argument("--scenarios", nargs="*", help="default: every bundled one without faults")
    args = ap.parse_args(argv)
    names = args.scenarios or default_scenarios()
    head = ["scenario", "s"] + [label for _, label in ESTIMATES]
    print("| " + " | ".join(head) + " |")
    print("|" + "|".join("---" for _ in head) + "|")
    for name in names:
        result = runner.run(scenario.load(name), backend=args.backend, seed=args.seed, ekf=True)
        print("| " + " | ".join(row(result)) + " |", flush=True)
    print("\nEach cell: final position error (m) / RMS position error over the run (m) / "
          "final heading error (deg), against the plant's ground truth; "
          f"backend {args.backend}, gyro seed {args.seed}.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
