"""One navigation script, two robots: tests/support/go_to_goal.py reaches its goal on the
Mega chair (``sim://``, ``simavr://``) and on the Eddie (``eddie+sim://``) without a
change; and on Eddie, a wall ahead stops the robot through PING))) and IR readings
read with the API, and the host deadman stops it when navigation code goes silent."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

import wcdrive
from tests.support.go_to_goal import go_to_goal
from wcdrive.eddie.robot import EddieRobot, gospd_counts

GOAL = (1.0, 0.5)


def truth(robot: wcdrive.Robot) -> tuple[float, float, float]:
    """The simulated board's ground truth behind either robot's port."""
    port = robot._port if isinstance(robot, EddieRobot) else robot._session.port  # type: ignore[attr-defined]
    return port.board.pose()


def _reach(url: str) -> None:
    with wcdrive.connect(url) as robot:
        assert isinstance(robot, wcdrive.Robot)
        x, y, _ = go_to_goal(robot, *GOAL)
        tx, ty, _ = truth(robot)
    print(f"{url}: odometry ({x:.3f}, {y:.3f}), truth ({tx:.3f}, {ty:.3f})")
    assert math.hypot(x - GOAL[0], y - GOAL[1]) < 0.08
    assert math.hypot(tx - GOAL[0], ty - GOAL[1]) < 0.12


def test_go_to_goal_on_sim() -> None:
    _reach("sim://?speed=2")                # twice the wall clock, as Eddie's below


def test_go_to_goal_on_eddie_sim() -> None:
    _reach("eddie+sim://?speed=2")


@pytest.mark.simavr
def test_go_to_goal_on_simavr(elf: Path) -> None:
    _reach(f"simavr://{elf}?realtime=1")


def test_set_velocity_is_the_ros_drivers_gospd() -> None:
    # ((v -/+ w S/2) / R) / (2 pi / 36), truncated: 0.5 m/s -> 37.6 -> 37 positions/s
    assert gospd_counts(0.5, 0.0) == (37, 37)
    assert gospd_counts(0.0, 1.0) == (-11, 11)          # 0.15 m/s at each wheel: 11.28
    assert gospd_counts(-0.2, 0.0) == (-15, -15)
    with pytest.raises(ValueError):
        gospd_counts(500.0, 0.0)


def test_a_wall_ahead_stops_eddie_through_ping_and_adc() -> None:
    with wcdrive.connect("eddie+sim://") as robot:
        assert isinstance(robot, EddieRobot)
        robot._port.board.add_wall((1.2, -1.0), (1.2, 1.0))       # type: ignore[attr-defined]
        stopped_at = None
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            pings = [d for d in robot.ping() if d is not None]
            irs = [d for d in robot.ir_distances() if d is not None]
            if (pings and min(pings) < 0.35) or (irs and min(irs) < 0.35):
                robot.stop()
                stopped_at = (min(pings) if pings else None, min(irs) if irs else None)
                break
            robot.set_velocity(0.25, 0.0)
            time.sleep(0.05)
        time.sleep(1.0)
        x, _, _ = truth(robot)
    assert stopped_at is not None, "never saw the wall"
    gap = 1.2 - (x + 0.2)                      # the sensors sit 0.2 m ahead of the axle
    print(f"stopped by (PING, IR) = {stopped_at}; sensors {gap:.3f} m from the wall at rest")
    assert stopped_at[0] is not None and stopped_at[1] is not None      # both sensor kinds see it
    assert 0.05 < gap < 0.35                   # stopped short of the wall, after the threshold


def test_host_deadman_stops_eddie_when_navigation_goes_silent() -> None:
    with wcdrive.connect("eddie+sim://") as robot:
        assert isinstance(robot, EddieRobot)
        robot.set_velocity(0.3, 0.0)
        time.sleep(1.5)                         # no more set_velocity: deadman after 0.5 s
        x1 = truth(robot)[0]
        time.sleep(1.0)
        x2 = truth(robot)[0]
        events = list(robot.events)
    assert any("deadman" in e for e in events), events
    assert 0.05 < x1 < 0.35 and abs(x2 - x1) < 0.01
