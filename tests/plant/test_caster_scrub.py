"""Caster scrub: it was 0 J in every scenario, because the patch's side
force carried no sliding. The tyre carries it by sliding (force / stiffness), so a
pivot scrubs and straight driving hardly does; the C kernel agrees with the Python
reference."""

from __future__ import annotations

import pytest

from wcdrive.plant import Plant
from wcdrive.sim import runner, scenario


def test_a_pivot_scrubs_the_casters_and_straight_driving_hardly() -> None:
    spin = runner.run(scenario.load("spin_360"))              # 360 degrees on the spot
    straight = runner.run(scenario.load("step_response"))     # straight, 16 s
    assert spin.truth.caster_scrub_energy > 0.005
    assert spin.truth.caster_scrub_time > 1.0
    assert straight.truth.caster_scrub_energy < 0.05 * spin.truth.caster_scrub_energy
    assert spin.metrics()["caster_scrub_energy_j"] == spin.truth.caster_scrub_energy


def test_the_kernel_counts_scrub_as_the_reference_does() -> None:
    fast, ref = Plant(), Plant(use_kernel=False)
    assert fast.uses_kernel
    for plant in (fast, ref):
        plant.set_drive(120, 1, 120, 0)                          # pivot: left back, right forward
        plant.advance(1500)
    assert fast.caster_scrub_energy > 0
    assert fast.caster_scrub_energy == pytest.approx(ref.caster_scrub_energy, rel=1e-6)
    assert fast.caster_scrub_time == pytest.approx(ref.caster_scrub_time, abs=2e-3)
