"""The rated-grade table: the steepest grade the chair climbs from rest at the driver's
current limit, by occupant mass (``ChairParams.rated_grade``).

    python benchmarks/rated_grade.py [--from 40] [--to 150] [--step 10]

Prints a markdown table: occupant mass (kg), the chair's total mass, the rated grade in
degrees and in percent (rise over run), for the default ``ChairParams``. A static
balance, worked out, not simulated: both motors at the current limit at stall against
the grade's pull and the rolling resistance (traction and tipping not counted).
"""

from __future__ import annotations

import argparse
import math

from wcdrive.plant import ChairParams


def table(masses: list[float], params: ChairParams | None = None) -> str:
    """The markdown table of the module docstring for these occupant masses (kg)."""
    p = params or ChairParams()
    rows = ["| occupant (kg) | total (kg) | rated grade (deg) | rated grade (%) |",
            "|---:|---:|---:|---:|"]
    for m in masses:
        grade = p.rated_grade(m)
        percent = 100 * math.tan(math.radians(grade))
        rows.append(f"| {m:.0f} | {p.chair_mass + m:.0f} | {grade:.2f} | {percent:.1f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    """Prints the table for the masses the arguments give."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="lo", type=float, default=40.0, help="lightest occupant (kg)")
    ap.add_argument("--to", dest="hi", type=float, default=150.0, help="heaviest occupant (kg)")
    ap.add_argument("--step", type=float, default=10.0, help="kg between rows")
    args = ap.parse_args(argv)
    n = math.floor((args.hi - args.lo) / args.step + 1e-9) + 1
    print(table([args.lo + k * args.step for k in range(n)]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
