"""The drives on which the motor rule took a hill for a dead motor, kept as fixed
cases. Under the rule that read the other wheel by its own effort count
(``effortRising``, main before the effort lead) a healthy chair latched a fault on the
first three, and a left motor dying on the 1:20 band was named ``MOTOR_R``, the healthy
side; the rule now asks whose effort leads (docs/safety.md, "One motor or the chair's
load"). The cases:

* the 1:20 band (2.86 degrees, inside every occupant's rated grade) at 1.0 m/s with a
  150 kg occupant: ``MOTOR_R``;
* a band at the 58 kg occupant's rated grade (5.68 degrees) at 1 m/s, hypothesis'
  shrunk counterexample of ``tests/sim/test_envelope_property.py``: ``MOTOR_L``;
* turning 10 s at 0.4 rad/s on a 4 degree slope at 0.5 m/s (``benchmarks/motor_rule.py``):
  ``MOTOR_L``;
* a 1:20 band down at 0.6 m/s with 80 kg (no fault under the old rule either: the descent);
* near the rated grade, on the band, a sharp turn that asks one wheel to stop or
  reverse (``benchmarks/envelope.py``'s drives 2337 and 2442): the other wheel, at the
  current limit, carries the chair alone while its partner brakes to its setpoint.
  Under the effort lead alone it latched ``MOTOR_R``/``MOTOR_L``; a partner held back
  by its own setpoint now excuses the lead.

And the eight drives of ``benchmarks/envelope.py`` (seed 0) that still latched a fault
under that rule, kept in ``tests/data/envelope_drives/``, all turning near the rated grade
or coming off a band: a wheel standing at full torque while its partner rolls back
(``ENC_STALL_L``: now the chair's limit), a P term beyond the clamp winding the integral
backward on a climb (``ENC_REVERSED_L``: the chair rolled back under its own PID), a
partner braking short of its setpoint as its PID unwinds off a descent (``MOTOR_L``,
``MOTOR_R``), and the outer wheel at the current limit 0.49 rad/s ahead of the inner one
(``MOTOR_R``: FAULT_EFFORT_LEAD 0.45). Among them the last two the encoders alone could
not tell from a fault, which the motors' currents do (docs/safety.md, "What the currents
say"): 176, a wheel standing across 94 % of its rated grade at duty 26 beside its turning
partner (``ENC_STALL_L``: it stands by its current), and 1913, a wheel winding its duty
up without a gain as the chair comes off a band at 2.68 m/s (``MOTOR_R``: its motor
draws 3 A the way it is driven).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from wcdrive.sim import runner, scenario

ENVELOPE_DRIVES = Path(__file__).parents[1] / "data" / "envelope_drives"


def _band(occupant: float, slope_deg: float, to_x: float, speed: float, seconds: float) -> str:
    return (f'name = "band"\nsettle_s = 0.5\nhost_rate_hz = 10\n[chair]\noccupant_mass = {occupant}\n'
            f"[world]\nslope_deg = 0.0\ndownhill_heading_deg = 0\n"
            f"[[world.ramp]]\nfrom_x = 1.0\nto_x = {to_x}\nslope_deg = {slope_deg}\n"
            f"[[segment]]\ncmdvel = [{speed}, 0.0]\nduration = {seconds}\n"
            f"[[segment]]\nstop = true\nduration = 3.0\n")


def _band_turn(occupant: float, slope_deg: float, to_x: float, speed: float, seconds: float,
               turn: tuple[float, float], host_hz: int, gains: tuple[float, float, float] | None) -> str:
    """Up a band at ``speed``, then ``turn`` (m/s, rad/s) for 2 s, then the stop."""
    params = "" if gains is None else "[params]\n" + "".join(
        f"{k}_{side} = {v}\n" for side in "lr" for k, v in zip(("kp", "ki", "kd"), gains, strict=True))
    return (f'name = "band_turn"\nsettle_s = 0.5\nhost_rate_hz = {host_hz}\n'
            f"[chair]\noccupant_mass = {occupant}\n{params}"
            f"[world]\nslope_deg = 0.0\ndownhill_heading_deg = 0\n"
            f"[[world.ramp]]\nfrom_x = 1.0\nto_x = {to_x}\nslope_deg = {slope_deg}\n"
            f"[[segment]]\ncmdvel = [{speed}, 0.0]\nduration = {seconds}\n"
            f"[[segment]]\ncmdvel = [{turn[0]}, {turn[1]}]\nduration = 2.0\n"
            f"[[segment]]\nstop = true\nduration = 3.0\n")


CASES = {
    "1in20_band_150kg_1mps": _band(150.0, -2.862, 4.6, 1.0, 6.0),
    "rated_band_58kg_1mps": _band(58.0, -5.68, 3.0, 1.0, 5.2),
    "1in20_band_down_80kg": _band(80.0, 2.862, 4.6, 0.6, 9.0),
    "rated_band_122kg_sharp_turn": _band_turn(122.0, -3.749, 4.9, 0.5, 6.7, (0.25, 0.89), 5, None),
    "rated_band_125kg_spin": _band_turn(125.0, -3.684, 2.8, 0.3, 7.0, (0.15, -0.97), 4,
                                        (2.64, 2.764, 0.162)),
    "turn_on_4deg_slope": ('name = "turn"\nsettle_s = 0.5\nhost_rate_hz = 10\n'
                           "[world]\nslope_deg = 4.0\ndownhill_heading_deg = 270.0\n"
                           "[[segment]]\ncmdvel = [0.5, 0.4]\nduration = 10.0\n"),
}


def _events(tmp_path: Path, text: str) -> list[str]:
    path = tmp_path / "case.toml"
    path.write_text(text)
    return [line for _, line in runner.run(scenario.load(str(path))).link.events]


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_healthy_chair_where_the_old_rule_saw_a_dead_motor_latches_nothing(tmp_path: Path,
                                                                            name: str) -> None:
    events = _events(tmp_path, CASES[name])
    assert not [e for e in events if e.startswith("EVT:FAULT")], events


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_dead_motor_on_the_1in20_band_is_named(tmp_path: Path, side: str) -> None:
    """The same band, the same load: a motor that dies on the ramp is found, on its side."""
    text = CASES["1in20_band_150kg_1mps"] + f'[[fault]]\nat = 3.5\nkind = "motor_dead"\nside = "{side}"\n'
    faults = [e for e in _events(tmp_path, text) if e.startswith("EVT:FAULT")]
    assert faults and faults[0] == f"EVT:FAULT,MOTOR_{side[0].upper()}", faults


@pytest.mark.parametrize("path", sorted(ENVELOPE_DRIVES.glob("*.toml")), ids=lambda p: p.stem)
def test_the_envelope_drives_that_faulted_latch_nothing(path: Path) -> None:
    """Each drive as ``benchmarks/envelope.py --failing`` wrote it: no ``EVT:FAULT``."""
    events = [line for _, line in runner.run(scenario.load(str(path))).link.events]
    assert not [e for e in events if e.startswith("EVT:FAULT")], events
