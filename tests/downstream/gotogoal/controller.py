"""Go to a goal (x, y): turn toward it, drive, slow down near it, stop inside ``tolerance``."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class GoToGoal:
    goal: tuple[float, float]
    tolerance: float = 0.10        # m
    max_linear: float = 0.5        # m/s
    max_angular: float = 1.0       # rad/s
    k_linear: float = 0.8
    k_angular: float = 2.0

    def command(self, pose: tuple[float, float, float]) -> tuple[float, float]:
        """The (linear m/s, angular rad/s) command for ``pose`` (x, y, heading)."""
        x, y, heading = pose
        dx, dy = self.goal[0] - x, self.goal[1] - y
        distance = math.hypot(dx, dy)
        if distance < self.tolerance:
            return 0.0, 0.0
        error = (math.atan2(dy, dx) - heading + math.pi) % (2 * math.pi) - math.pi
        angular = max(-self.max_angular, min(self.max_angular, self.k_angular * error))
        linear = min(self.max_linear, self.k_linear * distance) * max(0.0, math.cos(error)) ** 2
        return linear, angular

    def arrived(self, pose: tuple[float, float, float]) -> bool:
        return math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1]) < self.tolerance
