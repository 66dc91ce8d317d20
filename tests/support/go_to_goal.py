"""A go-to-goal navigation script on odometry, written once against the
``wcdrive.host.robot.Robot`` surface: ``set_velocity``, ``stop``, ``odometry``. It runs
unchanged on the Mega chair (``sim://``, ``simavr://``) and on the Eddie
(``eddie+sim://``): tests/eddie/test_eddie_navigation.py.

    python tests/support/go_to_goal.py eddie+sim:// 1.0 0.5
"""

from __future__ import annotations

import math
import sys
import time

import wcdrive


def go_to_goal(robot: wcdrive.Robot, goal_x: float, goal_y: float, *, tolerance: float = 0.05,
               timeout: float = 30.0, rate_hz: float = 10.0) -> tuple[float, float, float]:
    """Drives toward (goal_x, goal_y) in the odometry frame until within ``tolerance``;
    returns the odometry pose it stopped at."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pose = robot.odometry.pose
        dx, dy = goal_x - pose.x, goal_y - pose.y
        distance = math.hypot(dx, dy)
        if distance < tolerance:
            break
        bearing = math.remainder(math.atan2(dy, dx) - pose.theta, 2 * math.pi)
        angular = max(-0.8, min(0.8, 1.5 * bearing))
        linear = min(0.3, 0.6 * distance) * max(0.0, math.cos(bearing))
        robot.set_velocity(linear, angular)
        time.sleep(1.0 / rate_hz)
    robot.stop()
    time.sleep(0.5)
    pose = robot.odometry.pose
    return pose.x, pose.y, pose.theta


if __name__ == "__main__":
    url, gx, gy = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    with wcdrive.connect(url) as bot:
        print(go_to_goal(bot, gx, gy))
