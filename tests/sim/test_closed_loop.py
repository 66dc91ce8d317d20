"""Closed-loop scenarios: a ``path`` followed by pure pursuit on the host's
odometry at the cmd_vel rate, ending within the scenario's published tolerance of its
goal by the plant's ground truth; the open-loop scenarios say they are open loop."""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path

import pytest

from wcdrive.navigation.pure_pursuit import FollowParams, PurePursuit
from wcdrive.sim import runner, scenario
from wcdrive.tools.cli import main as wcdrive_main

CLOSED = ("square_closed", "l_shape_closed", "corridor_closed")


def _unicycle(path, params: FollowParams, rate: float = 10.0, seconds: float = 120.0):
    """An ideal chair that does what it is told, ``rate`` commands a second."""
    ctl = PurePursuit(path, params)
    x = y = th = 0.0
    legs = []
    for _ in range(int(seconds * rate)):
        v, w, done = ctl.command(x, y, th)
        legs.append(ctl.leg)
        if done:
            return (x, y), legs
        for _ in range(10):
            dt = 0.1 / rate
            x += v * math.cos(th) * dt
            y += v * math.sin(th) * dt
            th += w * dt
    raise AssertionError("never reached the goal")


def test_pure_pursuit_follows_a_closed_square_to_its_end() -> None:
    """The square ends where it starts: the controller must not stop at the start
    (the goal is there) nor skip to the last leg as it passes it; it takes every leg
    in order."""
    params = FollowParams()
    end, legs = _unicycle([(1, 0), (1, 1), (0, 1), (0, 0)], params)
    assert math.hypot(*end) <= 2 * params.goal_tolerance
    assert legs == sorted(legs) and set(legs) == {0, 1, 2, 3}
    assert legs.count(3) > 10                                    # the last leg was driven


def test_a_path_scenario_is_checked(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    for text, message in [
        ('path = [[1, 0]]\n[[segment]]\nstop = true\nduration = 1\n', "not both"),
        ('path = [[1, 0]]\n[follow]\nspeeed = 0.3\n', "unknown \\[follow\\] keys: speeed"),
        ('path = [[1, 0]]\n[follow]\nlocalization = "lidar"\n', "localization"),
        ('path = [1, 0]\n', "list of \\[x, y\\] points"),
    ]:
        bad.write_text(text)
        with pytest.raises(scenario.ScenarioError, match=message):
            scenario.load(str(bad))
    sc = scenario.load("square_closed")
    assert sc.closed_loop and sc.path == ((1, 0), (1, 1), (0, 1), (0, 0))
    assert not scenario.load("square").closed_loop


@pytest.mark.parametrize("name", CLOSED)
def test_closed_loop_scenarios_reach_their_goals_on_the_port(name: str) -> None:
    sc = scenario.load(name)
    result = runner.run(sc)
    m = result.metrics()
    assert m["closed_loop"] and m["goal_reached_s"] is not None
    assert m["goal_error_m"] <= sc.follow.truth_tolerance, m["goal_error_m"]
    assert m["goal_within_tolerance"] is True
    assert result.duration < sc.duration                         # ended once there
    assert not any(line.startswith("EVT:FAULT") for _, line in result.link.events)  # no detector tripped
    assert sc.path is not None
    for wx, wy in sc.path:                                       # and drove by every waypoint
        nearest = min(math.hypot(x - wx, y - wy) for x, y, _ in result.truth.pose)
        assert nearest <= max(0.15, sc.follow.truth_tolerance), (wx, wy, nearest)
    assert result.link.cmd_vel and all(abs(v) <= sc.follow.speed + 1e-9 for _, v, _ in result.link.cmd_vel)


@pytest.mark.simavr
def test_the_closed_l_reaches_its_goal_on_the_firmware() -> None:
    """The compiled firmware in simavr, the host steering by the lines it sends: the
    goal within tolerance, and the port replays the firmware's events identically."""
    sc = scenario.load("l_shape_closed")
    m = runner.run(sc, backend="simavr").metrics()
    assert m["goal_within_tolerance"] is True and m["goal_error_m"] <= sc.follow.truth_tolerance
    assert m["firmware_differences"] == 0


def test_the_list_labels_open_and_closed_loop() -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert wcdrive_main(["sim", "--list"]) == 0
    rows = {line.split()[0]: line for line in out.getvalue().splitlines()}
    for name in CLOSED:
        assert "closed loop" in rows[name]
    for name in ("square", "l_shape", "corridor_100m", "slip_turn"):
        assert "open loop" in rows[name]


def test_bench_run_refuses_a_closed_loop_scenario() -> None:
    """``wcdrive bench run`` replays timed segments; a path scenario has none."""
    from wcdrive.tools import bench

    with pytest.raises(scenario.ScenarioError, match="closed-loop"):
        bench.run_scenario("square_closed", "sim://")


def test_the_table_states_the_goal() -> None:
    from wcdrive.sim import report

    text = report.table(runner.run(scenario.load("l_shape_closed")))
    assert "goal (2.00, 1.00) reached at" in text and "(tolerance 0.10 m: within)" in text
