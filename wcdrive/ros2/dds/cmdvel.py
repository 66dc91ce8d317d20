"""Which ``/cmd_vel`` samples may drive the chair: ``CmdVelGate``.

A person sits in the chair, so a sample is driven only when it is fresh, finite and
in range; any other is dropped and counted by reason (``counts``), never clamped:

- ``stale``: a ``TwistStamped`` whose stamp is more than ``max_age`` s from the
  clock (``now``) either way: an old message, or a publisher whose clock is off. A
  zero stamp counts as "now", as Jazzy's ``diff_drive_controller`` takes it
  (``ros2 topic pub`` leaves the stamp zero). A plain ``Twist`` has no stamp.
- ``non_finite``: any of the six components NaN or infinite.
- ``out_of_range``: ``|linear.x| > max_linear`` or ``|angular.z| > max_angular``.

The other four components of a twist mean nothing to a differential drive and are
ignored, as ``diff_drive_controller`` does.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any


class CmdVelGate:
    """Checks ``/cmd_vel`` samples (module docstring); ``counts`` keeps the tallies:
    ``accepted`` and one per reason a sample was dropped."""

    def __init__(self, max_linear: float, max_angular: float, max_age: float = 0.5) -> None:
        self.max_linear, self.max_angular, self.max_age = max_linear, max_angular, max_age
        self.counts: Counter[str] = Counter()

    def check(self, twist: dict[str, Any], now: float, stamp: dict[str, int] | None = None
              ) -> tuple[float, float] | None:
        """``(linear, angular)`` to drive, or None (dropped, counted). ``twist``: a
        ``geometry_msgs/msg/Twist`` as a dict; ``stamp``: the header's stamp of a
        ``TwistStamped`` (``builtin_interfaces/msg/Time``), on the clock of ``now`` (s)."""
        reason = self._reason(twist, now, stamp)
        self.counts[reason or "accepted"] += 1
        if reason:
            return None
        return float(twist["linear"]["x"]), float(twist["angular"]["z"])

    def _reason(self, twist: dict[str, Any], now: float, stamp: dict[str, int] | None) -> str:
        values = [float(twist[part][axis]) for part in ("linear", "angular") for axis in "xyz"]
        if not all(math.isfinite(v) for v in values):
            return "non_finite"
        if stamp is not None and (stamp["sec"] or stamp["nanosec"]):
            age = now - (stamp["sec"] + stamp["nanosec"] * 1e-9)
            if not abs(age) <= self.max_age:
                return "stale"
        if abs(values[0]) > self.max_linear or abs(values[5]) > self.max_angular:
            return "out_of_range"
        return ""

    @property
    def dropped(self) -> int:
        """How many samples were dropped, for any reason."""
        return sum(n for reason, n in self.counts.items() if reason != "accepted")
