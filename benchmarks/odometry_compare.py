"""Seed 002's odometry comparison on the bundled worlds (docs/odometry.md, "Odometry
against the truth"): wheel odometry, the EKF (wheel velocities and the gyro), ICP on
the RPLidar S3's scans seeded by the wheels, ICP seeded by the EKF ("ICP + EKF"), and
ICP fused into the EKF (each ICP step a pose measurement), each against the plant's
ground truth (``wcdrive.sim.compare``), with and without
wheel slip:

* ``corridor_lidar``: 10 m down the hospital corridor at 0.5 m/s, closed loop;
* ``room_lidar``: round the furnished room's pillar at 0.4 m/s, closed loop, turning on
  the spot at each corner, the lidar mounted head down;
* dry: the tyres' mu 0.8 (``ChairParams.friction``); slip: the left tyre on a wet
  floor, mu 0.08 (``friction_left``, as the bundled ``slip_turn``). The host steers by
  its wheel odometry in both, so under slip the chair goes where its wheels' wrong
  estimate takes it, as a real one would.

Each error is at the scans' stamps (10 Hz): the final position error, the RMS of the
position error over the run, and the final heading error; ICP's fallbacks are the
scans where it kept its guess (not converged, degenerate, or a jump past 0.3 m or
15 deg). The run's seed seeds the gyro and the lidar's noise.

    python benchmarks/odometry_compare.py              # both worlds, seeds 0 to 2
    python benchmarks/odometry_compare.py --quick      # the corridor, seed 0
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from wcdrive.sim import runner, scenario  # noqa: E402
from wcdrive.sim.compare import ESTIMATES, Errors, compare  # noqa: E402

CONDITIONS = {"dry": {}, "slip (left tyre mu 0.08)": {"friction_left": 0.08}}


def one(name: str, chair: dict[str, float], seed: int) -> tuple[dict[str, Errors], dict[str, object], float]:
    """One run's errors, its figures and the seconds its ICP took."""
    sc = scenario.load(name)
    sc = dataclasses.replace(sc, chair={**sc.chair, **chair})
    result = runner.run(sc, seed=seed, ekf=True)
    t = time.perf_counter()
    errors = compare(result)
    return errors, result.metrics(), time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="the corridor only, seed 0")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 (the table: seed 0; ranges: all)")
    args = ap.parse_args()
    worlds = ["corridor_lidar"] if args.quick else ["corridor_lidar", "room_lidar"]
    seeds = [0] if args.quick else list(range(args.seeds))
    print("| world | floor | estimate | final error | RMS error | final heading error | ICP fallbacks |")
    print("|---|---|---|---|---|---|---|")
    notes = []
    for world in worlds:
        for label, chair in CONDITIONS.items():
            runs = [one(world, chair, seed) for seed in seeds]
            errors0, metrics0, icp_s = runs[0]
            for key, title in ESTIMATES.items():
                e = errors0[key]
                final = [r[0][key].final_m for r in runs]
                rng = "" if len(runs) == 1 else f" ({min(final) * 1e3:.1f} to {max(final) * 1e3:.1f})"
                fb = "" if e.fallbacks is None else f"{e.fallbacks} of {e.scans}"
                print(f"| {world} | {label} | {title} | {e.final_m * 1e3:.1f} mm{rng} "
                      f"| {e.rms_m * 1e3:.1f} mm | {e.heading_deg:+.2f} deg | {fb} |")
            goal = [r[1]["goal_error_m"] for r in runs]
            notes.append(f"{world}, {label}: {metrics0['simulated_s']} s simulated, {e.scans} scans, "
                         f"collisions {metrics0['collisions']}, true goal error "
                         f"{statistics.median(goal) * 1e3:.0f} mm (median of {len(runs)}), "
                         f"the three ICP estimates {icp_s:.1f} s (seed 0)")
    print()
    print(f"seed 0; the final error's range over seeds {seeds[0]} to {seeds[-1]} in brackets")
    for note in notes:
        print("- " + note)


if __name__ == "__main__":
    main()
