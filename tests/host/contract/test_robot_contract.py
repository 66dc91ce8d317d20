"""The ``Robot`` contract (``wcdrive.host.robot.Robot``), run over every robot wcdrive
drives, as the ``Port`` contract runs over every transport: ``Wheelchair`` on
``sim://`` and on ``simavr://`` (the compiled firmware), ``SteppedChair`` (simulated
time, no thread) and ``EddieRobot`` on ``eddie+sim://``. Navigation code written
against ``Robot`` gets the same behaviour from each: bad speeds refused before
anything is sent, a held command drives, a stop stops, the odometry and the wheel
angles follow, the samples reach ``on_telemetry``, and leaving ``with`` stops it.

Each robot is paced by its own ``telemetry()``: samples in wall time for the live
ones, in simulated time for the stepped chair (``Telemetry.time``)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import pytest

import wcdrive
from wcdrive.host.robot import Robot
from wcdrive.host.telemetry import Telemetry
from wcdrive.testing.stepped import SteppedChair

ROBOTS: dict[str, Callable[[], Robot]] = {
    "sim": lambda: wcdrive.connect("sim://"),
    "simavr": lambda: wcdrive.connect("simavr://?speed=1"),
    "stepped": SteppedChair,
    "eddie": lambda: wcdrive.connect("eddie+sim://"),
}


@pytest.fixture(params=[pytest.param(n, marks=pytest.mark.simavr) if n == "simavr" else n for n in ROBOTS])
def robot(request: pytest.FixtureRequest) -> Iterator[Robot]:
    made = ROBOTS[request.param]()
    try:
        yield made
    finally:
        made.close()


def _samples(robot: Robot, seconds: float, then: Callable[[], None] | None = None) -> list[Telemetry]:
    """The samples of the next ``seconds`` (by their ``time``), calling ``then`` after
    each; a robot that falls silent for 2 s ends it early."""
    out: list[Telemetry] = []
    for sample in robot.telemetry(timeout=2.0):
        out.append(sample)
        if then is not None:
            then()
        if sample.time - out[0].time >= seconds:
            break
    return out


def _hold(robot: Robot, linear: float, angular: float, seconds: float) -> list[Telemetry]:
    """``set_velocity`` again at every sample (>= 20 Hz) for ``seconds``."""
    robot.set_velocity(linear, angular)
    return _samples(robot, seconds, lambda: robot.set_velocity(linear, angular))


def test_it_is_a_robot(robot: Robot) -> None:
    assert isinstance(robot, Robot)
    linear, angular = robot.command_limits
    assert linear > 0 and angular > 0


@pytest.mark.parametrize("bad", [(math.nan, 0.0), (0.0, math.inf), (-math.inf, 0.0), "beyond"])
def test_a_bad_speed_is_refused_and_nothing_moves(robot: Robot, bad: object) -> None:
    linear_max, _ = robot.command_limits
    pair = (linear_max * 1.01, 0.0) if bad == "beyond" else bad
    assert isinstance(pair, tuple)
    with pytest.raises(ValueError):
        robot.set_velocity(*pair)
    samples = _samples(robot, 0.5)
    assert samples and all(abs(s.vel_left) < 0.05 and abs(s.vel_right) < 0.05 for s in samples)


def test_a_held_command_drives_and_the_odometry_and_wheels_follow(robot: Robot) -> None:
    seen: list[Telemetry] = []
    robot.on_telemetry(seen.append)
    start = robot.odometry.pose
    samples = _hold(robot, 0.3, 0.0, 2.0)
    end = robot.odometry.pose
    assert len(samples) >= 20 and seen, (len(samples), len(seen))
    travelled = math.hypot(end.x - start.x, end.y - start.y)
    assert 0.2 < travelled < 0.8, travelled
    left0, right0 = robot.wheel_angles(samples[0])
    left1, right1 = robot.wheel_angles(samples[-1])
    assert left1 > left0 + 1.0 and right1 > right0 + 1.0          # both wheels forward


def test_a_stop_stops_and_the_robot_stays(robot: Robot) -> None:
    _hold(robot, 0.3, 0.0, 1.0)
    robot.stop()
    _samples(robot, 1.5)
    rest = robot.odometry.pose
    last = _samples(robot, 1.0)
    assert last and all(abs(s.vel_left) < 0.05 and abs(s.vel_right) < 0.05 for s in last)
    moved = robot.odometry.pose
    assert math.hypot(moved.x - rest.x, moved.y - rest.y) < 0.01


def test_leaving_the_block_stops_it() -> None:
    chair = SteppedChair()
    with chair as robot:
        _hold(robot, 0.3, 0.0, 1.0)
    assert not chair.link_ok
    assert abs(chair.feedback.vel_left) < 0.05 if chair.feedback else False
