"""Path following for navigation code: a pure-pursuit controller that turns a pose
estimate into a ``cmd_vel``, as a host sends it at its command rate.

``PurePursuit(path, params).command(x, y, heading)`` returns ``(linear, angular,
done)``. The path is a list of waypoints, the chair starting at (0, 0); the controller
keeps its progress along the path (it never skips ahead to a later leg that passes
close by, as the last leg of a closed square does), steers toward the point
``lookahead`` ahead along the path (curvature ``2 y / d^2`` in the chair's frame),
turns on the spot when that point is more than 60 degrees off its heading, slows down
within a lookahead of the goal and stops (``done``) within ``goal_tolerance`` of it, or
once past the line through the goal square to the last leg, within twice that (a
chair that ends a little beside the goal does not circle back to it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class FollowParams:
    """How a path is followed (the scenario's ``[follow]`` table)."""

    speed: float = 0.3              # m/s cruise
    lookahead: float = 0.35         # m
    max_angular: float = 0.6        # rad/s
    goal_tolerance: float = 0.05    # m, by the host's own estimate
    timeout_s: float = 60.0         # s: the scenario ends here at the latest
    localization: str = "wheel"     # "wheel" (position-based odometry) or "ekf"
    truth_tolerance: float = 0.15   # m: the published bound on the true final error

    def __post_init__(self) -> None:
        if not 0.0 < self.speed <= 1.5:
            raise ValueError("speed must be within 0 .. 1.5 m/s")
        if not 0.05 <= self.lookahead <= 5.0:
            raise ValueError("lookahead must be within 0.05 .. 5 m")
        if not 0.0 < self.max_angular <= 2.0:
            raise ValueError("max_angular must be within 0 .. 2 rad/s")
        if not 0.0 < self.goal_tolerance < self.lookahead:
            raise ValueError("goal_tolerance must be positive and below the lookahead")
        if self.timeout_s <= 0:
            raise ValueError("timeout_s must be positive")
        if self.localization not in ("wheel", "ekf"):
            raise ValueError("localization must be 'wheel' or 'ekf'")
        if self.truth_tolerance <= 0:
            raise ValueError("truth_tolerance must be positive")


#: Beyond this angle to the lookahead point the chair turns on the spot.
TURN_IN_PLACE = math.radians(60.0)


class PurePursuit:
    """The controller (module docstring)."""

    def __init__(self, path: list[tuple[float, float]] | tuple[tuple[float, float], ...],
                 params: FollowParams | None = None, start: tuple[float, float] = (0.0, 0.0)) -> None:
        if not path:
            raise ValueError("a path needs at least one waypoint")
        self.points = [start, *[(float(x), float(y)) for x, y in path]]
        self.p = params or FollowParams()
        self.leg = 0                 # the leg (points[leg] -> points[leg + 1]) being followed
        self.done = False

    @property
    def goal(self) -> tuple[float, float]:
        """The last waypoint."""
        return self.points[-1]

    def _project(self, x: float, y: float, leg: int) -> tuple[float, float]:
        """(fraction along ``leg``, distance from it) of the point."""
        (ax, ay), (bx, by) = self.points[leg], self.points[leg + 1]
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        u = 0.0 if length2 == 0 else ((x - ax) * dx + (y - ay) * dy) / length2
        u = min(1.0, max(0.0, u))
        return u, math.hypot(ax + u * dx - x, ay + u * dy - y)

    def _lookahead_point(self, x: float, y: float) -> tuple[float, float]:
        # progress: move to the next leg once this one's projection reaches its end
        while self.leg < len(self.points) - 2 and self._project(x, y, self.leg)[0] >= 1.0:
            self.leg += 1
        u, _ = self._project(x, y, self.leg)
        (ax, ay), (bx, by) = self.points[self.leg], self.points[self.leg + 1]
        px, py = ax + u * (bx - ax), ay + u * (by - ay)
        remaining = self.p.lookahead
        leg = self.leg
        while True:
            ex, ey = self.points[leg + 1]
            d = math.hypot(ex - px, ey - py)
            if d >= remaining or leg == len(self.points) - 2:
                if d == 0:
                    return ex, ey
                f = min(1.0, remaining / d)
                return px + f * (ex - px), py + f * (ey - py)
            remaining -= d
            px, py = ex, ey
            leg += 1

    def command(self, x: float, y: float, heading: float) -> tuple[float, float, bool]:
        """The ``cmd_vel`` (m/s, rad/s) for the pose estimate, and whether the goal is
        reached (then it is (0, 0) from now on)."""
        gx, gy = self.goal
        to_goal = math.hypot(gx - x, gy - y)
        tx, ty = self._lookahead_point(x, y)
        last = self.leg == len(self.points) - 2
        if self.done or (last and (to_goal <= self.p.goal_tolerance
                                   or (self._project(x, y, self.leg)[0] >= 1.0
                                       and to_goal <= 2.0 * self.p.goal_tolerance))):
            self.done = True                 # there, or past the goal's line close by
            return 0.0, 0.0, True
        dx, dy = tx - x, ty - y
        c, s = math.cos(heading), math.sin(heading)
        fx, fy = c * dx + s * dy, -s * dx + c * dy     # in the chair's frame
        d2 = fx * fx + fy * fy
        angle = math.atan2(fy, fx)
        w_max = self.p.max_angular
        if abs(angle) > TURN_IN_PLACE:
            return 0.0, math.copysign(w_max, angle), False
        speed = self.p.speed
        if self.leg == len(self.points) - 2:
            speed = min(speed, max(0.05, speed * to_goal / self.p.lookahead))
        curvature = 2.0 * fy / d2 if d2 > 1e-9 else 0.0
        w = speed * curvature
        if abs(w) > w_max:                              # keep the curvature, slow down
            speed *= w_max / abs(w)
            w = math.copysign(w_max, w)
        return speed, w, False
