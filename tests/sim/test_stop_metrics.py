"""The stop figures of ``wcdrive sim --json`` (``SimResult.stop_metrics``, the floor's
keys of ``SimResult.metrics``): when the run's last stop begins
(``wcdrive.sim.runner.stop_time``), the chair's top speed after it, where and when it
came to rest, how far it drifts from there, and the grade it stood on.

Each can fail: the figures are held to speed profiles worked out by hand, to a chair
that cannot hold (both motors dead on 1:12, free to roll whatever the firmware does) and
to one parked on the level.
"""

from __future__ import annotations

import io
import json
import math
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest

from wcdrive.avr.timer0 import F_CPU
from wcdrive.plant.faults import Fault
from wcdrive.plant.terrain import Ramp, Terrain
from wcdrive.sim import runner, safety, scenario
from wcdrive.sim.result import BoardLog, GroundTruth, Odometry, SimResult
from wcdrive.sim.scenario import MOTION_START_S, Scenario, Segment
from wcdrive.tools.cli import main as wcdrive_main

GRADE_1IN12 = math.degrees(math.atan(1 / 12))
DT = 0.001


def _profile(speed: np.ndarray, stop_at: float | None) -> SimResult:
    """A run straight along x at ``speed`` (m/s, one a physics step of ``DT``), its
    pose logged every 50 ms as the board's ticks."""
    n = speed.size
    t = DT * np.arange(1, n + 1)
    x = np.cumsum(speed) * DT
    ticks = np.arange(0.05, n * DT + 1e-9, 0.05)
    pose = np.zeros((ticks.size, 3))
    pose[:, 0] = np.interp(ticks, t, x)
    zeros2 = np.zeros((ticks.size, 2))
    truth = GroundTruth(pose, zeros2, zeros2, step_time=t, step_speed=speed,
                        step_contact_speed=np.stack((speed, speed), axis=1), step_volts=np.zeros((n, 2)))
    board = BoardLog(ticks, zeros2, zeros2, zeros2, zeros2, np.round(ticks * F_CPU).astype(np.int64))
    odometry = Odometry(pose, pose, pose)
    return SimResult("profile", "port", n * DT, 1.0, truth, board, odometry, stop_at=stop_at)


def _rests_rolls_rests() -> np.ndarray:
    """0.5 m/s to 1 s, braking at 1 m/s^2 to rest, still to 4 s, then a roll at 0.05 m/s
    for 2 s (0.1 m), still to 10 s."""
    t = DT * np.arange(1, 10_001)
    speed = np.where(t <= 1.0, 0.5, np.clip(0.5 - (t - 1.0), 0.0, None))
    return np.where((t > 4.0) & (t <= 6.0), 0.05, speed)


# ---- the figures, on profiles worked out by hand ------------------------------------------
def test_the_figures_of_a_stop_worked_out_by_hand() -> None:
    m = _profile(_rests_rolls_rests(), stop_at=1.0).stop_metrics()
    assert m["stop_at_s"] == 1.0
    assert m["max_speed_after_stop_mps"] == pytest.approx(0.5, abs=2 * DT)
    # the first step below STANDSTILL_SPEED: 0.5 - (t - 1) < 0.01
    assert m["rest_at_s"] == pytest.approx(1.491, abs=1e-9)
    assert m["stopping_time_s"] == pytest.approx(0.491, abs=1e-9)
    assert m["stopping_distance_m"] == pytest.approx((0.5**2 - 0.01**2) / 2, abs=1e-3)
    assert m["travel_after_stop_m"] == pytest.approx(0.125 + 0.1, abs=1e-3)
    # counted from the first rest: the roll between the two rests is in the drift
    assert m["drift_parked_m"] == pytest.approx(0.1, abs=1e-3)


def test_the_drift_over_a_window_after_the_rest() -> None:
    result = _profile(_rests_rolls_rests(), stop_at=1.0)
    assert result.stop_metrics(parked_s=2.0)["drift_parked_m"] < 5e-4          # before the roll
    # to 5.0 s: a second of the roll
    assert result.stop_metrics(parked_s=5.0 - 1.491)["drift_parked_m"] == pytest.approx(0.05, abs=5e-4)


def test_a_chair_that_never_comes_to_rest_has_no_drift() -> None:
    t = DT * np.arange(1, 5001)
    m = _profile(np.where(t <= 1.0, 0.5, 0.05), stop_at=1.0).stop_metrics()
    assert m["rest_at_s"] is None and m["drift_parked_m"] is None and m["stopping_distance_m"] is None
    assert m["max_speed_after_stop_mps"] == pytest.approx(0.05)
    assert m["travel_after_stop_m"] == pytest.approx(0.05 * 4.0, abs=1e-6)


def test_without_a_stop_every_figure_is_none() -> None:
    m = _profile(np.full(2000, 0.3), stop_at=None).stop_metrics()
    assert set(m.values()) == {None}


# ---- when the last stop begins --------------------------------------------------------
def _stop_at(segments: tuple[Segment, ...], faults: tuple[Fault, ...] = (),
             events: list[tuple[float, str]] | None = None, settle_s: float = 1.0) -> float | None:
    sc = Scenario("s", "", segments, settle_s=settle_s, faults=faults)
    commands = [(round(t * F_CPU), data) for t, data in sc.host_commands() if t < sc.duration]
    return runner.stop_time(sc, runner.wire_schedule(commands, faults), events or [])


DRIVE = Segment("cmdvel", (0.5, 0.0), 2.0)
#: When the first segment starts (after the host's neutral command).
T0 = MOTION_START_S


def test_the_stop_is_the_start_of_the_last_stretch_without_motion() -> None:
    stop = Segment("stop", (), 2.0)
    assert _stop_at((DRIVE, stop, DRIVE, stop, Segment("cmdvel", (0.0, 0.0), 1.0))) == pytest.approx(6.0 + T0)
    assert _stop_at((DRIVE, stop, DRIVE)) == pytest.approx(6.0 + T0)               # the closing stop
    assert _stop_at((stop, Segment("silence", (), 2.0))) == 0.0               # parked from the start
    assert _stop_at((DRIVE,), settle_s=0.0) is None                            # the run ends driving


def test_a_silence_stops_from_the_last_byte_as_the_fault_figures_count() -> None:
    sc = scenario.load("fault_silence")
    commands = [(round(t * F_CPU), d) for t, d in sc.host_commands() if t < sc.duration]
    wire = runner.wire_schedule(commands)
    assert runner.stop_time(sc, wire, []) == runner.fault_time(sc, wire)
    assert _stop_at((DRIVE, Segment("silence", (), 2.0), Segment("stop", (), 1.0))) < 2.0 + T0


def test_a_latched_fault_or_a_lasting_link_cut_is_the_stop() -> None:
    stop = Segment("stop", (), 2.0)
    cut = Fault("encoder_cut", 1.0, "left")
    assert _stop_at((DRIVE, stop), (cut,), [(1.1, "EVT:FAULT,ENC_STALL_L")]) == 1.0
    assert _stop_at((DRIVE, stop), (cut,)) == pytest.approx(2.0 + T0)              # no fault latched
    assert _stop_at((DRIVE, stop), events=[(1.3, "EVT:FAULT,MOTOR_L")]) == 1.3   # none injected
    assert _stop_at((DRIVE, stop), (Fault("reset", 1.0),)) == pytest.approx(2.0 + T0)
    link = _stop_at((DRIVE, stop), (Fault("link_cut", 1.05),))
    assert link is not None and 0.92 < link < 1.05                             # the last byte
    assert _stop_at((DRIVE, stop), (Fault("link_cut", 1.05, duration=0.5),)) == pytest.approx(2.0 + T0)


# ---- on the plant ---------------------------------------------------------------------------
def test_a_chair_that_cannot_hold_drifts_on_1in12() -> None:
    """Both motors dead: nothing brakes, whatever the firmware does."""
    sc = Scenario("dead_1in12", "", (Segment("stop", (), 5.0),), settle_s=0.0,
                  faults=(Fault("motor_dead", 0.3, "both"),), terrain=Terrain(GRADE_1IN12))
    result = runner.run(sc)
    m = result.stop_metrics()
    assert m["stop_at_s"] == 0.0 and m["rest_at_s"] == pytest.approx(DT)
    rolled = math.hypot(*result.truth.pose[-1, :2])
    assert rolled > 2.0
    assert m["drift_parked_m"] == pytest.approx(rolled, abs=2e-3)
    assert m["max_speed_after_stop_mps"] == pytest.approx(result.truth.step_speed[-1], rel=1e-3)
    assert result.metrics()["slope_by_time"] == [[0.0, 5.0, pytest.approx(GRADE_1IN12)]]


def test_a_chair_parked_on_the_level_stays_put() -> None:
    m = runner.run(Scenario("level", "", (Segment("stop", (), 5.0),), settle_s=0.0)).stop_metrics()
    assert m["stop_at_s"] == 0.0 and m["rest_at_s"] == pytest.approx(DT)
    assert m["drift_parked_m"] < 1e-4 and m["max_speed_after_stop_mps"] < 1e-3


def test_after_a_stop_on_the_level_the_chair_only_slows() -> None:
    result = runner.run(Scenario("stop", "", (Segment("cmdvel", (0.5, 0.0), 3.0), Segment("stop", (), 8.0)),
                                 settle_s=0.0))
    m = result.stop_metrics()
    assert m["stop_at_s"] == pytest.approx(3.0 + MOTION_START_S)
    assert m["max_speed_after_stop_mps"] == pytest.approx(safety.speed_at(result, 3.0 + T0 + DT), abs=1e-3)
    assert 0.1 < m["stopping_distance_m"] < 0.5
    # a straight line: the drift is the path after the rest
    assert m["drift_parked_m"] == pytest.approx(m["travel_after_stop_m"] - m["stopping_distance_m"], abs=2e-3)


def test_the_grade_under_the_chair_by_time() -> None:
    """Over a 1:20 band from 0.5 m to 1.0 m and off it: the ranges change where the axle
    crosses the band's edges."""
    grade = math.degrees(math.atan(1 / 20))
    sc = Scenario("band", "", (Segment("cmdvel", (0.5, 0.0), 4.0),), settle_s=0.5,
                  terrain=Terrain(0.0, 0.0, (Ramp(0.5, 1.0, -grade),)))
    result = runner.run(sc)
    ranges = result.metrics()["slope_by_time"]
    assert [r[2] for r in ranges] == [0.0, pytest.approx(-grade), 0.0]
    assert ranges[0][0] == 0.0 and ranges[-1][1] == result.duration
    ticks, x = result.board.tick_time, result.truth.pose[:, 0]
    for (_, edge, _), at in zip(ranges[:2], (0.5, 1.0), strict=True):
        k = int(np.searchsorted(ticks, edge))
        assert x[k - 1] < at <= x[k]


def test_sim_json_reports_the_floor_and_the_stop(tmp_path: Path) -> None:
    path = tmp_path / "parked.toml"
    path.write_text("settle_s = 0.0\n[world]\nslope_deg = 2.862\n[[segment]]\nstop = true\nduration = 3\n")
    out = io.StringIO()
    with redirect_stdout(out):
        assert wcdrive_main(["sim", str(path), "--json", "--no-plots"]) == 0
    [m] = json.loads(out.getvalue())
    assert m["slope_deg"] == 2.862 and m["downhill_heading_deg"] == 0.0 and m["ramps"] == []
    assert m["slope_by_time"] == [[0.0, 3.0, 2.862]]
    for key in ("stop_at_s", "max_speed_after_stop_mps", "rest_at_s", "stopping_time_s",
                "stopping_distance_m", "travel_after_stop_m", "drift_parked_m"):
        assert isinstance(m[key], float), key
    assert all(isinstance(t, float) and line.startswith("EVT:") for t, line in m["events"])
    path.write_text("settle_s = 0.5\n[world]\ndownhill_heading_deg = 90\n[[world.ramp]]\nfrom_x = 1\n"
                    "to_x = 4.6\nslope_deg = -4.764\n[[segment]]\ncmdvel = [0.3, 0.0]\nduration = 1\n")
    with redirect_stdout(io.StringIO()) as out:
        assert wcdrive_main(["sim", str(path), "--json", "--no-plots"]) == 0
    [m] = json.loads(out.getvalue())
    assert m["ramps"] == [{"from_x": 1.0, "to_x": 4.6, "slope_deg": -4.764}]
    assert m["downhill_heading_deg"] == 90.0 and m["slope_by_time"] == [[0.0, 1.5, 0.0]]
    assert m["stop_at_s"] == pytest.approx(1.0 + MOTION_START_S)
