"""A scenario's ``[world]`` table: parsed into the plant's ``Terrain``, checked with
clear errors, every table's keys checked, and a level ``[world]`` the same run, bit for
bit, as none."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wcdrive.eddie import runner as eddie_runner
from wcdrive.plant.terrain import Ramp, Terrain
from wcdrive.sim import runner, scenario
from wcdrive.sim.scenario import ScenarioError

DRIVE = '[[segment]]\ncmdvel = [0.4, 0.1]\nduration = 2.0\n'
EDDIE_SCENARIOS = sorted((Path(eddie_runner.__file__).parent / "scenarios").glob("*.toml"))


def _write(tmp_path: Path, text: str, name: str = "w") -> str:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'settle_s = 0.5\n{text}\n{DRIVE}')
    return str(path)


@pytest.mark.parametrize("path", scenario.bundled(), ids=lambda p: p.stem)
def test_every_bundled_scenario_loads_and_only_the_ramp_ones_tilt_the_floor(path: Path) -> None:
    assert scenario.load(str(path)).terrain.flat != path.stem.startswith(("ramp_", "kerb_cut_"))


@pytest.mark.parametrize("path", EDDIE_SCENARIOS, ids=lambda p: p.stem)
def test_every_eddie_scenario_loads(path: Path) -> None:
    assert eddie_runner.load(path.stem).source == path
    assert eddie_runner.load(str(path)).source == path


def test_world_table_becomes_the_terrain(tmp_path: Path) -> None:
    sc = scenario.load(_write(tmp_path, "[world]\nslope_deg = 3.5\ndownhill_heading_deg = 90\n"
                                        "[[world.ramp]]\nfrom_x = 4\nto_x = 6\nslope_deg = -5\n"
                                        "[[world.ramp]]\nfrom_x = 1\nto_x = 2.5\nslope_deg = 6\n"))
    assert sc.terrain == Terrain(3.5, 90.0, (Ramp(1.0, 2.5, 6.0), Ramp(4.0, 6.0, -5.0)))
    assert sc.terrain.grade_at(0.0, 2.0) == pytest.approx((np.radians(6.0), np.radians(90.0)))
    assert sc.terrain.grade_at(9.0, 3.0)[0] == pytest.approx(np.radians(3.5))     # between the bands
    assert sc.terrain.grade_at(0.0, 6.0)[0] == pytest.approx(np.radians(3.5))     # to_x is past the band
    assert scenario.load(_write(tmp_path, "")).terrain == Terrain()


@pytest.mark.parametrize(("text", "message"), [
    ("[world]\nslope_deg = 30\n", r"\[world\]: slope_deg must be within \+-30"),
    ("[world]\nslope_deg = -31.5\n", "slope_deg must be within"),
    ("[world]\nslope_deg = nan\n", "slope_deg must be a finite number"),
    ("[world]\ndownhill_heading_deg = inf\n", "downhill_heading_deg must be a finite number"),
    ('[world]\nslope_deg = "steep"\n', "slope_deg must be a finite number"),
    ("[world]\nslop_deg = 3\n", r"\[world\]: unknown keys: slop_deg"),
    ("[[world.ramp]]\nfrom_x = 2\nto_x = 1\nslope_deg = 3\n",
     r"world.ramp 1: from_x \(2\) must be less than to_x"),
    ("[[world.ramp]]\nfrom_x = 1\nto_x = 1\nslope_deg = 3\n", "must be less than"),
    ("[[world.ramp]]\nfrom_x = 1\nto_x = 2\nslope_deg = 45\n", "world.ramp 1: slope_deg must be within"),
    ("[[world.ramp]]\nfrom_x = 1\nto_x = 2\n", "world.ramp 1 needs slope_deg"),
    ("[[world.ramp]]\nfrom_x = 1\nto_x = 2\nslope_deg = 3\ngrip = 1\n", "world.ramp 1: unknown keys: grip"),
    ("[[world.ramp]]\nfrom_x = 0\nto_x = 2\nslope_deg = 3\n"
     "[[world.ramp]]\nfrom_x = 1.5\nto_x = 3\nslope_deg = 2\n",
     r"ramps \[0, 2\] and \[1.5, 3\] overlap"),
    ("[world]\nramp = 3\n", r"\[\[world.ramp\]\] tables"),
    ("world = 3\n", r"world is a table"),
    ("[wrold]\nslope_deg = 3\n", "unknown keys at the top level: wrold"),
    ("sttle_s = 1\n", "unknown keys at the top level: sttle_s"),
    ("[[wall]]\na = [1, 0]\nb = [1, 1]\n", "unknown keys at the top level: wall"),
])
def test_world_errors_name_the_field(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        scenario.load(_write(tmp_path, text))


def test_segment_keys_are_checked(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text("[[segment]]\ncmdvel = [0.2, 0.0]\nduraton = 2\n")
    with pytest.raises(ScenarioError, match="segment 1: unknown keys: duraton"):
        scenario.load(str(path))


def test_a_level_world_runs_as_no_world(tmp_path: Path) -> None:
    """A ``[world]`` of slope 0, and one whose only ramp is far from the chair's path (the
    plant then looks the grade up every step and finds none), give the same run, bit for
    bit, as no ``[world]``."""
    plain = runner.run(scenario.load(_write(tmp_path, "", "plain")))
    for name, world in [("level", "[world]\nslope_deg = 0.0\ndownhill_heading_deg = 45\n"),
                        ("far", "[[world.ramp]]\nfrom_x = 50\nto_x = 60\nslope_deg = 5\n")]:
        sc = scenario.load(_write(tmp_path, world, name))
        assert sc.terrain.flat == (name == "level")
        other = runner.run(sc)
        for field in ("pose", "wheel_speed", "caster", "step_speed", "step_contact_speed"):
            assert np.array_equal(getattr(plain.truth, field), getattr(other.truth, field)), (name, field)
        assert plain.truth.caster_scrub_energy == other.truth.caster_scrub_energy
        assert np.array_equal(plain.board.pwm, other.board.pwm)


def test_the_runner_puts_the_chair_on_the_scenario_floor(tmp_path: Path) -> None:
    """Driving the same command up a 4 degree grade (the floor falls toward -x, the chair
    drives toward +x), the firmware needs more duty than on the level."""
    level = runner.run(scenario.load(_write(tmp_path, "", "plain")))
    uphill = runner.run(scenario.load(_write(tmp_path, "[world]\nslope_deg = 4\ndownhill_heading_deg = 180\n",
                                             "uphill")))
    t = level.board.tick_time
    cruise = (t > 1.0) & (t < 2.0)
    assert np.mean(np.abs(uphill.board.pwm[cruise])) > np.mean(np.abs(level.board.pwm[cruise])) + 10
