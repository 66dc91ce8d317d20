"""The Eddie's geometry and sensor figures, for hosts and the simulator alike: the wheel
and encoder figures, the sensors' mounts and ranges, and the IR sensor's curve.

No simulator here (no pymunk): ``wcdrive.eddie.robot`` reads these on the host side.
The figures and their sources are in ``wcdrive.eddie.plant``'s docstring and
docs/eddie.md.
"""

from __future__ import annotations

import dataclasses
import math

POSITIONS_PER_REV = 36
WHEEL_RADIUS = 0.0762
WHEEL_SEPARATION = 0.3


def positions(angle_left: float, angle_right: float) -> tuple[int, int]:
    """The Position Controllers' counts for these wheel angles (rad, forward +)."""
    scale = POSITIONS_PER_REV / (2.0 * math.pi)
    return math.floor(angle_left * scale), math.floor(angle_right * scale)


@dataclasses.dataclass(frozen=True)
class Mount:
    """A sensor on the base: ahead of the axle, left of the centre line (m), facing
    ``yaw`` (rad, counter-clockwise from forward)."""

    ahead: float
    left: float
    yaw: float


PING_MOUNTS = {0: Mount(0.20, 0.06, 0.0), 1: Mount(0.20, -0.06, 0.0)}
PING_RANGE = (0.02, 3.0)
PING_HALF_ANGLE = math.radians(15.0)
IR_MOUNTS = {1: Mount(0.19, 0.08, math.radians(30.0)), 2: Mount(0.20, 0.0, 0.0),
             3: Mount(0.19, -0.08, math.radians(-30.0))}
IR_RANGE = (0.10, 0.80)
IR_NOISE_V = 0.015
ADC_VREF = 5.0


def ir_volts(distance: float | None) -> float:
    """The IR sensor's output for a wall ``distance`` m away (None: nothing seen)."""
    if distance is None or distance > IR_RANGE[1]:
        return 0.25
    d_cm = max(distance, 1e-3) * 100.0
    if d_cm < 10.0:
        return (27.86 / 10.0) ** (1 / 1.15) * d_cm / 10.0
    return float((27.86 / d_cm) ** (1 / 1.15))


def ir_distance(counts: int) -> float | None:
    """The inverse, for hosts: an ADC count (12-bit) to metres in 0.10..0.80, None when
    the reading is below the 0.80 m level (nothing in range)."""
    volts = counts / 4096.0 * ADC_VREF
    if volts < ir_volts(IR_RANGE[1]):
        return None
    return min(max(27.86 / volts ** 1.15 / 100.0, IR_RANGE[0]), IR_RANGE[1])
