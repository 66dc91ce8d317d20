"""``wcdrive sim --robot eddie``: the bundled scenarios on the simulated Eddie, the
odometry's error against ground truth within docs/eddie.md's figures, walls from a
scenario seen by the PING))) sensors, and the host deadman in the silence scenarios."""

from __future__ import annotations

import json

import pytest

from wcdrive.eddie import runner
from wcdrive.tools.cli import main

#: docs/eddie.md's table, with headroom: scenario -> (final mm, heading deg)
BOUNDS = {"square": (60, 2.0), "l_shape": (30, 1.0), "spin_360": (20, 2.0), "step_response": (30, 0.5),
          "reversal_pivot": (20, 0.5), "watchdog": (20, 0.5)}


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_odometry_error_on_eddie_within_the_published_figures(name: str) -> None:
    result = runner.run(runner.load(name))
    final_mm, heading_deg = BOUNDS[name]
    assert result.path_length_m > 0.02
    assert result.final_error_m * 1000 < final_mm
    assert result.final_heading_error_deg < heading_deg


def test_silence_makes_the_host_deadman_stop_eddie() -> None:
    for name in ("watchdog", "fault_silence"):
        assert runner.run(runner.load(name)).deadman_stops == 1


def test_a_scenario_wall_is_what_the_ping_sensors_see() -> None:
    result = runner.run(runner.load("wall_ahead"))
    assert result.nearest_ping is not None
    reading, true = result.nearest_ping
    assert 0.2 < true < 0.4                         # 1.5 m wall, 0.97 m driven, sensors 0.2 m ahead
    assert abs(reading - true) < 0.03               # 3 mm + 1 % noise, 1.1 mm units


def test_cli_sim_robot_eddie_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "--robot", "eddie", "spin_360", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out[0]["name"] == "spin_360" and out[0]["final_error_m"] < 0.02


def test_the_list_shows_eddie_s_own_scenarios_for_eddie(capsys: pytest.CaptureFixture[str]) -> None:
    """``wcdrive sim --robot eddie --list`` adds Eddie's own scenarios (the wall);
    the Mega's list does not have them."""
    assert main(["sim", "--robot", "eddie", "--list"]) == 0
    eddie = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert main(["sim", "--list"]) == 0
    mega = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert "wall_ahead" in eddie and "wall_ahead" not in mega
    assert set(mega) < set(eddie)
