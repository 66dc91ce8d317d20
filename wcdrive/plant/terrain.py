"""The floor under the chair: a uniform grade, and bands of it with grades of their own.

``Terrain(slope_deg, downhill_heading_deg, ramps)``: the floor falls at ``slope_deg``
toward the world heading ``downhill_heading_deg`` (0 = +x, counter-clockwise positive);
each ``Ramp`` is a band across that direction, from ``from_x`` to ``to_x`` measured along
it (``x cos h + y sin h``, m), where the floor has the ramp's grade instead. A negative
grade rises toward the downhill heading. ``grade_at(x, y)`` is what the plant asks each
step, at the drive axle's midpoint.

The floor is planar within a band, so the grade changes as a step at a band's edge:
the plant sees the whole chair on the grade under its axle (a point model of the floor).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

__all__ = ["MAX_RAMPS", "MAX_SLOPE_DEG", "Ramp", "Terrain"]

#: degrees: the steepest grade a floor may have (well beyond any a power chair climbs).
MAX_SLOPE_DEG = 30.0
#: Ramp bands a terrain may hold (the C kernel's fixed arrays).
MAX_RAMPS = 8


@dataclass(frozen=True)
class Ramp:
    """A band of the floor with grade ``slope_deg`` between ``from_x`` and ``to_x``
    (m along the terrain's downhill heading)."""

    from_x: float
    to_x: float
    slope_deg: float

    def __post_init__(self) -> None:
        for name in ("from_x", "to_x", "slope_deg"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, not {value!r}")
        _check_slope(self.slope_deg)
        if not self.from_x < self.to_x:
            raise ValueError(f"from_x ({self.from_x}) must be less than to_x ({self.to_x})")


@dataclass(frozen=True)
class Terrain:
    """The floor of the module docstring; ``Terrain()`` is the flat floor. Raises
    ValueError for a non-finite value, a grade of 30 degrees or more, or ramps that
    overlap."""

    slope_deg: float = 0.0
    downhill_heading_deg: float = 0.0
    ramps: tuple[Ramp, ...] = ()

    def __post_init__(self) -> None:
        for name in ("slope_deg", "downhill_heading_deg"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, not {value!r}")
        _check_slope(self.slope_deg)
        ramps = tuple(sorted(self.ramps, key=lambda r: r.from_x))
        if len(ramps) > MAX_RAMPS:
            raise ValueError(f"at most {MAX_RAMPS} ramps, not {len(ramps)}")
        for a, b in itertools.pairwise(ramps):
            if b.from_x < a.to_x:
                raise ValueError(f"ramps [{a.from_x}, {a.to_x}] and [{b.from_x}, {b.to_x}] overlap")
        object.__setattr__(self, "ramps", ramps)

    @property
    def flat(self) -> bool:
        """Whether the floor is level everywhere (the plant then skips the grade)."""
        return self.slope_deg == 0.0 and all(r.slope_deg == 0.0 for r in self.ramps)

    @property
    def downhill_heading(self) -> float:
        """rad: the world heading the floor falls toward."""
        return math.radians(self.downhill_heading_deg)

    def along(self, x: float, y: float) -> float:
        """m: the point's distance along the downhill heading (the ramps' ``from_x``, ``to_x``)."""
        h = self.downhill_heading
        return x * math.cos(h) + y * math.sin(h)

    def grade_at(self, x: float, y: float) -> tuple[float, float]:
        """(grade in rad, downhill heading in rad) of the floor at world point (x, y)."""
        s = self.along(x, y)
        for r in self.ramps:
            if r.from_x <= s < r.to_x:
                return math.radians(r.slope_deg), self.downhill_heading
        return math.radians(self.slope_deg), self.downhill_heading


def _check_slope(slope_deg: float) -> None:
    if not abs(slope_deg) < MAX_SLOPE_DEG:
        raise ValueError(f"slope_deg must be within +-{MAX_SLOPE_DEG:g} degrees, not {slope_deg}")
