"""No false alarm anywhere in the chair's operating envelope: a hypothesis property over
the drives of ``wcdrive.testing.envelope`` (through ``strategies.envelope_drives``), on
the port with the pymunk chair.

The drives: uniform grades and cross-slopes, ramp bands up and down with their
level-to-ramp and ramp-to-level transitions (the chair stopping beyond the band or on
it), every grade up to the rated grade of the drawn occupant (40 to 150 kg), speeds up
to the full-speed command, turns up to 1 rad/s, host rates 4 to 100 Hz, the default
gains or a set drawn over the accepted ranges for both wheels; and beyond the envelope,
1:8 kerb cuts up and down.

The property: a healthy chair never latches an ``EVT:FAULT`` (beyond the envelope
neither: there the board's limit events are the right answer), and within 90 % of the
rated grade sends no limit event (``EVT:STALLED_ON_GRADE``, ``EVT:OVERSPEED``,
``EVT:ROLLAWAY``) either. At the rated grade itself the motors are at their current
limit with nothing to spare (``ChairParams.rated_grade``: a static balance), and a
climb at speed there may truly be beyond them (40 kg up 6.52 degrees at 1 m/s stalls);
the 10 % margin is the one ``tests/sim/test_grade_false_alarms.py`` keeps.

A failure prints the drive's scenario TOML: ``wcdrive sim FILE.toml`` replays it.
``benchmarks/envelope.py`` sweeps the same space with the figures.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings

from tests.conftest import thorough
from wcdrive.sim import runner, scenario
from wcdrive.testing import envelope as ev
from wcdrive.testing.strategies import envelope_drives


def _run(tmp_path_factory, drive: ev.Drive) -> ev.Verdict:
    path = Path(tmp_path_factory.mktemp("envelope")) / "drive.toml"
    path.write_text(drive.toml())
    return ev.judge(runner.run(scenario.load(str(path))).link.events)


#: The classes inside the envelope, the ramp bands at the ends (hypothesis draws the
#: ends of a choice often).
INSIDE = ("band_up", "uniform", "cross", "band_down")
#: The share of the rated grade within which a limit event is a false alarm too.
LIMIT_FREE = 0.9


@settings(max_examples=300 if thorough() else 60, deadline=None)
@given(drive=envelope_drives(INSIDE))
def test_a_healthy_chair_inside_its_envelope_sends_no_alarm(tmp_path_factory, drive: ev.Drive) -> None:
    verdict = _run(tmp_path_factory, drive)
    assert not verdict.faults, f"{drive.describe()}: {verdict.faults}\n{drive.toml()}"
    if drive.grade_fraction <= LIMIT_FREE:
        assert not verdict.limits, f"{drive.describe()}: {verdict.limits}\n{drive.toml()}"


@settings(max_examples=100 if thorough() else 20, deadline=None)
@given(drive=envelope_drives(ev.BEYOND))
def test_a_healthy_chair_on_a_kerb_cut_latches_no_fault_while_it_drives(tmp_path_factory,
                                                                      drive: ev.Drive) -> None:
    """Beyond the rated grade the board's limit events are the right answer, a fault
    never, while the chair drives straight: no fault before its first limit event nor
    before its turn. Once a limit has parked it, a hold that cannot carry the cut lets
    the chair roll back and may latch ``ENC_REVERSED`` (docs/safety.md, "Not safe yet";
    pinned below); a turn after the cut may latch a motor fault (docs/safety.md, "The
    envelope": 23 of 300 kerb cuts latch a fault)."""
    verdict = _run(tmp_path_factory, drive)
    first_limit = min((t for t, _ in verdict.limits), default=float("inf"))
    early = [f for f in verdict.faults if f[0] < min(first_limit, drive.drive_s)]
    assert not early, f"{drive.describe()}: {verdict.faults}\n{drive.toml()}"


@pytest.mark.xfail(strict=True, reason="known: beyond what the hold carries, the held wheels' rollback "
                   "latches ENC_REVERSED (docs/safety.md, Not safe yet)")
def test_a_chair_parked_by_its_limit_on_a_kerb_cut_rolls_back_without_a_fault(tmp_path: Path) -> None:
    """1:8 up at 0.5 m/s with 140 kg: STALLED_ON_GRADE parks the chair, the hold (the
    current limit: 3.6 degrees for 130 kg, less for 140) cannot carry 7.13 degrees,
    ROLLAWAY, and the held wheels' runaway latches ENC_REVERSED_L at 4.40 s. The goal is
    a bounded rollback under limit events only; this turns red when that is met. (With
    130 kg it latched too until the host's neutral command moved the drive 0.15 s later;
    now 130 kg rolls back under ROLLAWAY alone: the outcome turns on such details, the
    defect does not.)"""
    path = tmp_path / "kerb.toml"
    path.write_text('name = "kerb"\nhost_rate_hz = 10\nsettle_s = 0.5\n[chair]\noccupant_mass = 140\n'
                    "[world]\nslope_deg = 0.0\ndownhill_heading_deg = 0\n"
                    "[[world.ramp]]\nfrom_x = 1.0\nto_x = 2.2\nslope_deg = -7.125\n"
                    "[[segment]]\ncmdvel = [0.5, 0.0]\nduration = 4.0\n"
                    "[[segment]]\nstop = true\nduration = 3.0\n")
    verdict = ev.judge(runner.run(scenario.load(str(path))).link.events)
    assert [line for _, line in verdict.limits][:1] == ["EVT:STALLED_ON_GRADE"]
    assert not verdict.faults, verdict.faults


def test_the_drives_cover_the_envelope_and_beyond(tmp_path: Path) -> None:
    """The generator's classes and bounds, checked over seeded draws: every class comes,
    each grade is within the occupant's rated grade inside the envelope and a 1:8 cut
    beyond it, and the scenario file it writes loads."""
    from wcdrive.hil.traces import RandomDraw

    drives = [ev.drive(RandomDraw(i), ev.INSIDE + ev.BEYOND) for i in range(200)]
    assert {d.case for d in drives} == set(ev.INSIDE + ev.BEYOND)
    assert all(d.grade_deg <= d.rated_deg + 1e-9 for d in drives if d.inside)
    assert all(d.grade_deg > d.rated_deg for d in drives if not d.inside)
    assert max(d.speed for d in drives) == ev.MAX_LINEAR
    assert {d.host_rate_hz for d in drives} == set(ev.HOST_RATES)
    assert any(d.gains is None for d in drives) and any(d.gains is not None for d in drives)
    assert 0.2 < sum(d.brake for d in drives) / len(drives) < 0.45
    braked = [d for d in drives if d.brake and d.gains is not None][:2]
    for i, d in enumerate(drives[:8] + braked):
        path = tmp_path / f"drive{i}.toml"
        path.write_text(d.with_fault("motor_dead", 1.0, "left").toml())
        sc = scenario.load(str(path))
        assert sc.params().occupant_mass == d.occupant and len(sc.faults) == 1
        assert sc.params().parking_brake == d.brake
        assert sc.board_params.get("brake_fitted", 0) == (1 if d.brake else 0)
        assert (sc.board_params.get("kp_l") is not None) == (d.gains is not None)
